//! SDO: the server a device runs and the client a master uses, each speaking expedited,
//! segmented and block transfers (with CRC), with abort codes and timeouts.
//!
//! Both are state machines driven by frames and time; they never block and never read a
//! clock. The server's buffers are sized when it is made, so serving never allocates.

use alloc::collections::VecDeque;
use alloc::vec::Vec;
use core::time::Duration;

use bywire_core::frame::Frame;
use bywire_core::time::Timestamp;

use crate::abort::Abort;
use crate::nmt::{classic, cob_id};
use crate::queue::EventQueue;

/// Frames one SDO exchange may queue at once: a whole block (127 segments) and its end.
pub const OUTBOX: usize = 136;

/// The largest block a server or client offers (CiA 301 allows 1..=127 segments).
pub const MAX_BLOCK: u8 = 127;

/// How long a server waits for the client's next request in a transfer.
pub const SERVER_TIMEOUT: Duration = Duration::from_millis(1_000);

/// CRC-16/XMODEM (polynomial 0x1021, initial 0), the block transfer CRC.
pub fn crc16(crc: u16, bytes: &[u8]) -> u16 {
    bytes.iter().fold(crc, |mut crc, byte| {
        crc ^= u16::from(*byte) << 8;
        for _ in 0..8 {
            crc = if crc & 0x8000 != 0 {
                (crc << 1) ^ 0x1021
            } else {
                crc << 1
            };
        }
        crc
    })
}

/// The objects a server serves: the device supplies them, and judges writes.
pub trait Objects {
    /// Copy the value of `index:sub` into `into` (cleared first; its capacity is the server's
    /// buffer size: a longer value is [`Abort::OutOfMemory`]).
    fn upload(&mut self, index: u16, sub: u8, into: &mut Vec<u8>) -> Result<(), Abort>;
    /// Whether a download of `size` bytes (if known) to `index:sub` could be accepted; asked
    /// at the start of a transfer so a bad target aborts before any data moves.
    fn check_download(&self, index: u16, sub: u8, size: Option<usize>) -> Result<(), Abort>;
    /// Write `data` to `index:sub`, checked in full; nothing changes when refused.
    fn download(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<(), Abort>;
}

/// The index and sub-index a request names (as much of them as a short frame has).
fn index_of(data: &[u8]) -> (u16, u8) {
    let byte = |at: usize| data.get(at).copied().unwrap_or(0);
    (u16::from_le_bytes([byte(1), byte(2)]), byte(3))
}

fn u32_at4(data: &[u8]) -> u32 {
    match data {
        [_, _, _, _, a, b, c, d, ..] => u32::from_le_bytes([*a, *b, *c, *d]),
        _ => 0,
    }
}

fn with_index(command: u8, index: u16, sub: u8, tail: [u8; 4]) -> [u8; 8] {
    let [lo, hi] = index.to_le_bytes();
    let [a, b, c, d] = tail;
    [command, lo, hi, sub, a, b, c, d]
}

/// The abort frame payload.
pub fn abort_payload(index: u16, sub: u8, abort: Abort) -> [u8; 8] {
    with_index(0x80, index, sub, abort.code().to_le_bytes())
}

/// Seven bytes of `data` from `offset` (zero-padded) and how many were real.
fn segment_at(data: &[u8], offset: usize) -> ([u8; 7], usize) {
    let mut bytes = [0u8; 7];
    let real = data.get(offset..).unwrap_or(&[]);
    let n = real.len().min(7);
    if let (Some(to), Some(from)) = (bytes.get_mut(..n), real.get(..n)) {
        to.copy_from_slice(from);
    }
    (bytes, n)
}

fn segment_frame(command: u8, bytes: [u8; 7]) -> [u8; 8] {
    let [a, b, c, d, e, f, g] = bytes;
    [command, a, b, c, d, e, f, g]
}

/// Segments needed for `len` bytes in block mode (at least one).
fn segment_count(len: usize) -> usize {
    len.div_ceil(7).max(1)
}

/// Unused bytes in the last segment of `len` bytes.
fn unused_in_last(len: usize) -> u8 {
    let used = len - (segment_count(len) - 1) * 7;
    u8::try_from(7 - used.min(7)).unwrap_or(0)
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
/// What a block-upload server waits for.
enum UploadBlockPhase {
    Start,
    Ack { block_start: usize, sent: u8 },
    End,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum ServerState {
    Idle,
    DownloadSegmented {
        index: u16,
        sub: u8,
        toggle: bool,
        size: Option<usize>,
    },
    UploadSegmented {
        index: u16,
        sub: u8,
        toggle: bool,
        offset: usize,
    },
    DownloadBlock {
        index: u16,
        sub: u8,
        size: Option<usize>,
        crc: bool,
        expected: u8,
        acked_final: bool,
    },
    UploadBlock {
        index: u16,
        sub: u8,
        crc: bool,
        block_size: u8,
        phase: UploadBlockPhase,
    },
}

/// An SDO server (default channel: requests on `0x600 + node`, responses on `0x580 + node`).
#[derive(Debug, Clone)]
pub struct SdoServer {
    rx: u16,
    tx: u16,
    state: ServerState,
    buffer: Vec<u8>,
    deadline: Option<Timestamp>,
    outbox: EventQueue<Frame, OUTBOX>,
    /// Transfers aborted by this server.
    pub aborts_sent: u64,
}

impl SdoServer {
    /// A server for `node` whose largest object is `buffer_size` bytes.
    pub fn new(node: u8, buffer_size: usize) -> SdoServer {
        SdoServer {
            rx: 0x600 + u16::from(node & 0x7F),
            tx: 0x580 + u16::from(node & 0x7F),
            state: ServerState::Idle,
            buffer: Vec::with_capacity(buffer_size.max(8)),
            deadline: None,
            outbox: EventQueue::new(),
            aborts_sent: 0,
        }
    }

    /// The COB-ID requests arrive on.
    pub fn request_id(&self) -> u16 {
        self.rx
    }

    /// No transfer under way.
    pub fn is_idle(&self) -> bool {
        self.state == ServerState::Idle
    }

    /// Forget any transfer (NMT reset, entering stopped).
    pub fn reset(&mut self) {
        self.state = ServerState::Idle;
        self.deadline = None;
        self.outbox.clear();
    }

    fn respond(&mut self, payload: [u8; 8]) {
        let _ = self.outbox.push(classic(self.tx, &payload));
    }

    fn abort(&mut self, index: u16, sub: u8, abort: Abort) {
        self.respond(abort_payload(index, sub, abort));
        self.aborts_sent = self.aborts_sent.saturating_add(1);
        self.state = ServerState::Idle;
        self.deadline = None;
    }

    /// Take in a frame; requests on this server's channel are served.
    pub fn on_frame(&mut self, now: Timestamp, frame: &Frame, objects: &mut dyn Objects) {
        if cob_id(frame) != Some(self.rx) || frame.is_remote() {
            return;
        }
        let data = frame.data();
        let (index, sub) = index_of(data);
        let Ok(request) = <[u8; 8]>::try_from(data) else {
            // CiA 301 requests are always eight bytes.
            let (index, sub) = self.transfer_target().unwrap_or((index, sub));
            self.abort(index, sub, Abort::InvalidCommand);
            return;
        };
        self.deadline = Some(now.saturating_add(SERVER_TIMEOUT));
        match self.serve(request, objects) {
            Ok(()) => {}
            Err(abort) => {
                let (index, sub) = self.transfer_target().unwrap_or((index, sub));
                self.abort(index, sub, abort);
            }
        }
        if self.state == ServerState::Idle {
            self.deadline = None;
        }
    }

    fn transfer_target(&self) -> Option<(u16, u8)> {
        match self.state {
            ServerState::Idle => None,
            ServerState::DownloadSegmented { index, sub, .. }
            | ServerState::UploadSegmented { index, sub, .. }
            | ServerState::DownloadBlock { index, sub, .. }
            | ServerState::UploadBlock { index, sub, .. } => Some((index, sub)),
        }
    }

    fn serve(&mut self, request: [u8; 8], objects: &mut dyn Objects) -> Result<(), Abort> {
        let command = request[0];
        let (index, sub) = index_of(&request);
        // During a block download every frame is a segment, whatever its first byte says.
        if let ServerState::DownloadBlock {
            acked_final: false, ..
        } = self.state
        {
            return self.download_block_segment(request);
        }
        match command >> 5 {
            1 => self.initiate_download(request, objects),
            0 => self.download_segment(request, objects),
            2 => self.initiate_upload(index, sub, objects),
            3 => self.upload_segment(command),
            4 => {
                // The client aborted: no answer.
                self.state = ServerState::Idle;
                Ok(())
            }
            5 => self.block_upload(request, objects),
            6 => self.block_download(request, objects),
            _ => Err(Abort::InvalidCommand),
        }
    }

    fn initiate_download(
        &mut self,
        request: [u8; 8],
        objects: &mut dyn Objects,
    ) -> Result<(), Abort> {
        if self.state != ServerState::Idle {
            // A new initiate replaces a stale transfer (the client gave up on it).
            self.state = ServerState::Idle;
        }
        let command = request[0];
        let (index, sub) = index_of(&request);
        let expedited = command & 0x02 != 0;
        let size_indicated = command & 0x01 != 0;
        if expedited {
            let size = if size_indicated {
                4 - usize::from((command >> 2) & 0x03)
            } else {
                4
            };
            let data = request.get(4..4 + size).ok_or(Abort::InvalidCommand)?;
            objects.download(index, sub, data)?;
        } else {
            let size =
                size_indicated.then(|| usize::try_from(u32_at4(&request)).unwrap_or(usize::MAX));
            if size.is_some_and(|size| size > self.buffer.capacity()) {
                return Err(Abort::OutOfMemory);
            }
            objects.check_download(index, sub, size)?;
            self.buffer.clear();
            self.state = ServerState::DownloadSegmented {
                index,
                sub,
                toggle: false,
                size,
            };
        }
        self.respond(with_index(0x60, index, sub, [0; 4]));
        Ok(())
    }

    fn download_segment(
        &mut self,
        request: [u8; 8],
        objects: &mut dyn Objects,
    ) -> Result<(), Abort> {
        let ServerState::DownloadSegmented {
            index,
            sub,
            toggle,
            size,
        } = self.state
        else {
            return Err(Abort::InvalidCommand);
        };
        let command = request[0];
        if (command & 0x10 != 0) != toggle {
            return Err(Abort::ToggleNotAlternated);
        }
        let unused = usize::from((command >> 1) & 0x07);
        let last = command & 0x01 != 0;
        let bytes = request.get(1..8 - unused).unwrap_or(&[]);
        if self.buffer.len() + bytes.len() > self.buffer.capacity() {
            return Err(Abort::OutOfMemory);
        }
        self.buffer.extend_from_slice(bytes);
        if last {
            if size.is_some_and(|size| size != self.buffer.len()) {
                return Err(Abort::LengthMismatch);
            }
            objects.download(index, sub, &self.buffer)?;
            self.state = ServerState::Idle;
        } else {
            self.state = ServerState::DownloadSegmented {
                index,
                sub,
                toggle: !toggle,
                size,
            };
        }
        self.respond([0x20 | (u8::from(toggle) << 4), 0, 0, 0, 0, 0, 0, 0]);
        Ok(())
    }

    fn initiate_upload(
        &mut self,
        index: u16,
        sub: u8,
        objects: &mut dyn Objects,
    ) -> Result<(), Abort> {
        self.state = ServerState::Idle;
        objects.upload(index, sub, &mut self.buffer)?;
        let len = self.buffer.len();
        if (1..=4).contains(&len) {
            let mut tail = [0u8; 4];
            if let (Some(to), Some(from)) = (tail.get_mut(..len), self.buffer.get(..len)) {
                to.copy_from_slice(from);
            }
            let unused = u8::try_from(4 - len).unwrap_or(0);
            self.respond(with_index(0x43 | (unused << 2), index, sub, tail));
        } else {
            let size = u32::try_from(len).map_err(|_| Abort::OutOfMemory)?;
            self.respond(with_index(0x41, index, sub, size.to_le_bytes()));
            self.state = ServerState::UploadSegmented {
                index,
                sub,
                toggle: false,
                offset: 0,
            };
        }
        Ok(())
    }

    fn upload_segment(&mut self, command: u8) -> Result<(), Abort> {
        let ServerState::UploadSegmented {
            index,
            sub,
            toggle,
            offset,
        } = self.state
        else {
            return Err(Abort::InvalidCommand);
        };
        if (command & 0x10 != 0) != toggle {
            return Err(Abort::ToggleNotAlternated);
        }
        let (bytes, n) = segment_at(&self.buffer, offset);
        let offset = offset + n;
        let last = offset >= self.buffer.len();
        let unused = u8::try_from(7 - n).unwrap_or(0);
        self.respond(segment_frame(
            (u8::from(toggle) << 4) | (unused << 1) | u8::from(last),
            bytes,
        ));
        self.state = if last {
            ServerState::Idle
        } else {
            ServerState::UploadSegmented {
                index,
                sub,
                toggle: !toggle,
                offset,
            }
        };
        Ok(())
    }

    fn block_upload(&mut self, request: [u8; 8], objects: &mut dyn Objects) -> Result<(), Abort> {
        let command = request[0];
        match (command & 0x03, self.state) {
            (0, _) => {
                let (index, sub) = index_of(&request);
                let block_size = request[4];
                let switch_threshold = usize::from(request[5]);
                if block_size == 0 || block_size > MAX_BLOCK {
                    self.state = ServerState::Idle;
                    return Err(Abort::InvalidBlockSize);
                }
                objects.upload(index, sub, &mut self.buffer)?;
                let len = self.buffer.len();
                if len == 0 || len <= switch_threshold {
                    // CiA 301 lets the server switch to a normal upload (the protocol
                    // switch threshold, or nothing to send in blocks).
                    return self.initiate_upload(index, sub, objects);
                }
                let size = u32::try_from(len).map_err(|_| Abort::OutOfMemory)?;
                let crc = command & 0x04 != 0;
                self.respond(with_index(
                    0xC2 | (u8::from(crc) << 2),
                    index,
                    sub,
                    size.to_le_bytes(),
                ));
                self.state = ServerState::UploadBlock {
                    index,
                    sub,
                    crc,
                    block_size,
                    phase: UploadBlockPhase::Start,
                };
                Ok(())
            }
            (
                3,
                ServerState::UploadBlock {
                    index,
                    sub,
                    crc,
                    block_size,
                    phase: UploadBlockPhase::Start,
                },
            ) => {
                let sent = self.send_block(0, block_size);
                self.state = ServerState::UploadBlock {
                    index,
                    sub,
                    crc,
                    block_size,
                    phase: UploadBlockPhase::Ack {
                        block_start: 0,
                        sent,
                    },
                };
                Ok(())
            }
            (
                2,
                ServerState::UploadBlock {
                    index,
                    sub,
                    crc,
                    phase: UploadBlockPhase::Ack { block_start, sent },
                    ..
                },
            ) => {
                let acked = request[1];
                let block_size = request[2];
                if acked > sent {
                    return Err(Abort::InvalidSequence);
                }
                if block_size == 0 || block_size > MAX_BLOCK {
                    return Err(Abort::InvalidBlockSize);
                }
                let next = block_start + 7 * usize::from(acked);
                if next >= self.buffer.len() {
                    let len = self.buffer.len();
                    let check = if crc { crc16(0, &self.buffer) } else { 0 };
                    let [lo, hi] = check.to_le_bytes();
                    self.respond([0xC1 | (unused_in_last(len) << 2), lo, hi, 0, 0, 0, 0, 0]);
                    self.state = ServerState::UploadBlock {
                        index,
                        sub,
                        crc,
                        block_size,
                        phase: UploadBlockPhase::End,
                    };
                } else {
                    let sent = self.send_block(next, block_size);
                    self.state = ServerState::UploadBlock {
                        index,
                        sub,
                        crc,
                        block_size,
                        phase: UploadBlockPhase::Ack {
                            block_start: next,
                            sent,
                        },
                    };
                }
                Ok(())
            }
            (
                1,
                ServerState::UploadBlock {
                    phase: UploadBlockPhase::End,
                    ..
                },
            ) => {
                self.state = ServerState::Idle;
                Ok(())
            }
            _ => Err(Abort::InvalidCommand),
        }
    }

    /// Queue one block of segments from `start`; how many were sent.
    fn send_block(&mut self, start: usize, block_size: u8) -> u8 {
        let mut sent = 0u8;
        let mut offset = start;
        while sent < block_size {
            let (bytes, n) = segment_at(&self.buffer, offset);
            offset += n;
            sent += 1;
            let last = offset >= self.buffer.len();
            let _ = self.outbox.push(classic(
                self.tx,
                &segment_frame(sent | if last { 0x80 } else { 0 }, bytes),
            ));
            if last {
                break;
            }
        }
        sent
    }

    fn block_download(&mut self, request: [u8; 8], objects: &mut dyn Objects) -> Result<(), Abort> {
        let command = request[0];
        match (command & 0x01, self.state) {
            (0, _) => {
                let (index, sub) = index_of(&request);
                let size = (command & 0x02 != 0)
                    .then(|| usize::try_from(u32_at4(&request)).unwrap_or(usize::MAX));
                self.state = ServerState::Idle;
                if size.is_some_and(|size| size > self.buffer.capacity()) {
                    return Err(Abort::OutOfMemory);
                }
                objects.check_download(index, sub, size)?;
                self.buffer.clear();
                let crc = command & 0x04 != 0;
                self.respond(with_index(
                    0xA0 | (u8::from(crc) << 2),
                    index,
                    sub,
                    [MAX_BLOCK, 0, 0, 0],
                ));
                self.state = ServerState::DownloadBlock {
                    index,
                    sub,
                    size,
                    crc,
                    expected: 1,
                    acked_final: false,
                };
                Ok(())
            }
            (
                1,
                ServerState::DownloadBlock {
                    index,
                    sub,
                    size,
                    crc,
                    acked_final: true,
                    ..
                },
            ) => {
                let unused = usize::from((command >> 2) & 0x07);
                let len = self.buffer.len().saturating_sub(unused);
                self.buffer.truncate(len);
                if size.is_some_and(|size| size != len) {
                    return Err(Abort::LengthMismatch);
                }
                if crc && crc16(0, &self.buffer) != u16::from_le_bytes([request[1], request[2]]) {
                    return Err(Abort::CrcError);
                }
                objects.download(index, sub, &self.buffer)?;
                self.state = ServerState::Idle;
                self.respond([0xA1, 0, 0, 0, 0, 0, 0, 0]);
                Ok(())
            }
            _ => Err(Abort::InvalidCommand),
        }
    }

    fn download_block_segment(&mut self, request: [u8; 8]) -> Result<(), Abort> {
        let ServerState::DownloadBlock {
            index,
            sub,
            size,
            crc,
            expected,
            ..
        } = self.state
        else {
            return Err(Abort::InvalidCommand);
        };
        let sequence = request[0] & 0x7F;
        let last = request[0] & 0x80 != 0;
        if sequence == 0 || sequence > MAX_BLOCK {
            return Err(Abort::InvalidSequence);
        }
        let in_order = sequence == expected;
        if in_order {
            if self.buffer.len() + 7 > self.buffer.capacity() {
                return Err(Abort::OutOfMemory);
            }
            self.buffer
                .extend_from_slice(request.get(1..).unwrap_or(&[]));
        }
        let acked = if in_order { sequence } else { expected - 1 };
        if sequence == MAX_BLOCK || last {
            // End of a block: acknowledge what arrived in order; the client repeats the rest.
            self.respond([0xA2, acked, MAX_BLOCK, 0, 0, 0, 0, 0]);
            self.state = ServerState::DownloadBlock {
                index,
                sub,
                size,
                crc,
                expected: 1,
                acked_final: last && in_order,
            };
        } else if in_order {
            self.state = ServerState::DownloadBlock {
                index,
                sub,
                size,
                crc,
                expected: expected + 1,
                acked_final: false,
            };
        }
        Ok(())
    }

    /// Abort a transfer the client has left waiting too long; send queued responses.
    pub fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Frame)) {
        if self.deadline.is_some_and(|deadline| now >= deadline) {
            if let Some((index, sub)) = self.transfer_target() {
                self.abort(index, sub, Abort::Timeout);
            }
            self.deadline = None;
        }
        while let Some(frame) = self.outbox.pop() {
            out(frame);
        }
    }

    /// When a transfer would time out, or now if responses wait.
    pub fn next_deadline(&self) -> Option<Timestamp> {
        if !self.outbox.is_empty() {
            return Some(Timestamp::ZERO);
        }
        self.deadline
    }
}

/// How a client moves data.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum TransferMode {
    /// Expedited up to 4 bytes, segmented above.
    #[default]
    Auto,
    /// Segmented even for small values.
    Segmented,
    /// Block transfer with CRC (the server may switch an upload to a normal one).
    Block,
}

/// Why a client transfer failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum SdoError {
    /// The server aborted.
    #[error("the server aborted: {0}")]
    Aborted(Abort),
    /// No response within the client's timeout (the client sent an abort).
    #[error("no response within the timeout")]
    Timeout,
    /// The server answered out of protocol (the client sent this abort).
    #[error("the server answered out of protocol: {0}")]
    Protocol(Abort),
}

/// A finished client transfer.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SdoOutcome {
    /// The ticket the request was given.
    pub ticket: u32,
    /// The server's node.
    pub node: u8,
    /// The object.
    pub index: u16,
    /// Its sub-index.
    pub sub: u8,
    /// Uploaded bytes (empty for a download), or why it failed.
    pub result: Result<Vec<u8>, SdoError>,
}

#[derive(Debug, Clone, PartialEq, Eq)]
struct Request {
    ticket: u32,
    node: u8,
    index: u16,
    sub: u8,
    mode: TransferMode,
    /// `Some` for a download.
    data: Option<Vec<u8>>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum ClientPhase {
    /// Initiate sent, waiting for the response.
    Initiated,
    /// Segmented upload/download: waiting for the segment response with this toggle.
    Segment { toggle: bool },
    /// Block upload: receiving segments; `expected` next sequence number.
    UploadBlock {
        expected: u8,
        crc: bool,
        size: Option<usize>,
        complete: bool,
    },
    /// Block download: a block from `block_start` sent, `sent` segments.
    DownloadBlock {
        block_start: usize,
        sent: u8,
        block_size: u8,
        crc: bool,
    },
    /// Block download: end sent.
    DownloadBlockEnd,
}

/// An SDO client: requests are queued (bounded) and served one at a time.
#[derive(Debug, Clone)]
pub struct SdoClient {
    queue: VecDeque<Request>,
    capacity: usize,
    current: Option<(Request, ClientPhase)>,
    /// Bytes received (uploads) or the offset sent (segmented downloads).
    buffer: Vec<u8>,
    offset: usize,
    timeout: Duration,
    deadline: Option<Timestamp>,
    outbox: EventQueue<Frame, OUTBOX>,
    outcomes: VecDeque<SdoOutcome>,
    next_ticket: u32,
}

/// The client's request queue is full.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("the SDO client's request queue is full")]
pub struct QueueFull;

impl SdoClient {
    /// A client holding up to `capacity` waiting requests, giving servers `timeout` to answer.
    pub fn new(capacity: usize, timeout: Duration) -> SdoClient {
        SdoClient {
            queue: VecDeque::with_capacity(capacity),
            capacity,
            current: None,
            buffer: Vec::new(),
            offset: 0,
            timeout,
            deadline: None,
            outbox: EventQueue::new(),
            outcomes: VecDeque::with_capacity(capacity + 1),
            next_ticket: 1,
        }
    }

    fn enqueue(
        &mut self,
        node: u8,
        index: u16,
        sub: u8,
        mode: TransferMode,
        data: Option<Vec<u8>>,
    ) -> Result<u32, QueueFull> {
        if self.queue.len() >= self.capacity {
            return Err(QueueFull);
        }
        let ticket = self.next_ticket;
        self.next_ticket = self.next_ticket.wrapping_add(1).max(1);
        self.queue.push_back(Request {
            ticket,
            node,
            index,
            sub,
            mode,
            data,
        });
        Ok(ticket)
    }

    /// Queue a read of `index:sub` from `node`.
    pub fn upload(
        &mut self,
        node: u8,
        index: u16,
        sub: u8,
        mode: TransferMode,
    ) -> Result<u32, QueueFull> {
        self.enqueue(node, index, sub, mode, None)
    }

    /// Queue a write of `data` to `index:sub` of `node`.
    pub fn download(
        &mut self,
        node: u8,
        index: u16,
        sub: u8,
        data: &[u8],
        mode: TransferMode,
    ) -> Result<u32, QueueFull> {
        self.enqueue(node, index, sub, mode, Some(data.to_vec()))
    }

    /// Nothing queued or under way.
    pub fn is_idle(&self) -> bool {
        self.current.is_none() && self.queue.is_empty()
    }

    /// The next finished transfer.
    pub fn take_outcome(&mut self) -> Option<SdoOutcome> {
        self.outcomes.pop_front()
    }

    fn send(&mut self, node: u8, payload: [u8; 8]) {
        let _ = self
            .outbox
            .push(classic(0x600 + u16::from(node & 0x7F), &payload));
    }

    fn finish(&mut self, result: Result<Vec<u8>, SdoError>) {
        if let Some((request, _)) = self.current.take() {
            self.outcomes.push_back(SdoOutcome {
                ticket: request.ticket,
                node: request.node,
                index: request.index,
                sub: request.sub,
                result,
            });
        }
        self.deadline = None;
    }

    /// Give up on the transfer with `abort` sent to the server.
    fn fail(&mut self, abort: Abort, error: SdoError) {
        if let Some((request, _)) = &self.current {
            let (node, index, sub) = (request.node, request.index, request.sub);
            self.send(node, abort_payload(index, sub, abort));
        }
        self.finish(Err(error));
    }

    fn start(&mut self, now: Timestamp) {
        let Some(request) = self.queue.pop_front() else {
            return;
        };
        self.buffer.clear();
        self.offset = 0;
        let (node, index, sub) = (request.node, request.index, request.sub);
        let payload = match (&request.data, request.mode) {
            (None, TransferMode::Block) => with_index(0xA4, index, sub, [MAX_BLOCK, 0, 0, 0]),
            (None, _) => with_index(0x40, index, sub, [0; 4]),
            (Some(data), TransferMode::Block) => {
                let size = u32::try_from(data.len()).unwrap_or(u32::MAX);
                with_index(0xC6, index, sub, size.to_le_bytes())
            }
            (Some(data), TransferMode::Auto) if (1..=4).contains(&data.len()) => {
                let mut tail = [0u8; 4];
                if let (Some(to), Some(from)) = (tail.get_mut(..data.len()), data.get(..)) {
                    to.copy_from_slice(from);
                }
                let unused = u8::try_from(4 - data.len()).unwrap_or(0);
                with_index(0x23 | (unused << 2), index, sub, tail)
            }
            (Some(data), _) => {
                let size = u32::try_from(data.len()).unwrap_or(u32::MAX);
                with_index(0x21, index, sub, size.to_le_bytes())
            }
        };
        self.current = Some((request, ClientPhase::Initiated));
        self.send(node, payload);
        self.deadline = Some(now.saturating_add(self.timeout));
    }

    /// Take in a frame; responses from the server of the transfer under way advance it.
    pub fn on_frame(&mut self, now: Timestamp, frame: &Frame) {
        let Some((request, phase)) = &self.current else {
            return;
        };
        if cob_id(frame) != Some(0x580 + u16::from(request.node & 0x7F)) || frame.is_remote() {
            return;
        }
        let (request, phase) = (request.clone(), *phase);
        let Ok(response) = <[u8; 8]>::try_from(frame.data()) else {
            self.fail(
                Abort::InvalidCommand,
                SdoError::Protocol(Abort::InvalidCommand),
            );
            return;
        };
        self.deadline = Some(now.saturating_add(self.timeout));
        // Segments of a block upload may begin with any byte.
        let in_block_segments = matches!(
            phase,
            ClientPhase::UploadBlock {
                complete: false,
                ..
            }
        );
        if response[0] == 0x80 && !in_block_segments {
            self.finish(Err(SdoError::Aborted(Abort::from_code(u32_at4(&response)))));
            return;
        }
        if let Err(abort) = self.advance(&request, phase, response) {
            self.fail(abort, SdoError::Protocol(abort));
        }
    }

    fn check_target(request: &Request, response: &[u8; 8]) -> Result<(), Abort> {
        if index_of(response) == (request.index, request.sub) {
            Ok(())
        } else {
            Err(Abort::General)
        }
    }

    fn set_phase(&mut self, phase: ClientPhase) {
        if let Some((_, current)) = &mut self.current {
            *current = phase;
        }
    }

    fn advance(
        &mut self,
        request: &Request,
        phase: ClientPhase,
        response: [u8; 8],
    ) -> Result<(), Abort> {
        let command = response[0];
        let node = request.node;
        match (phase, &request.data) {
            (ClientPhase::Initiated, None) => match command >> 5 {
                2 => {
                    Self::check_target(request, &response)?;
                    if command & 0x02 != 0 {
                        let size = if command & 0x01 != 0 {
                            4 - usize::from((command >> 2) & 0x03)
                        } else {
                            4
                        };
                        let data = response.get(4..4 + size).unwrap_or(&[]).to_vec();
                        self.finish(Ok(data));
                    } else {
                        self.send(node, [0x60, 0, 0, 0, 0, 0, 0, 0]);
                        self.set_phase(ClientPhase::Segment { toggle: false });
                    }
                    Ok(())
                }
                6 if request.mode == TransferMode::Block && command & 0x01 == 0 => {
                    Self::check_target(request, &response)?;
                    let size = (command & 0x02 != 0)
                        .then(|| usize::try_from(u32_at4(&response)).unwrap_or(usize::MAX));
                    self.send(node, [0xA3, 0, 0, 0, 0, 0, 0, 0]);
                    self.set_phase(ClientPhase::UploadBlock {
                        expected: 1,
                        crc: command & 0x04 != 0,
                        size,
                        complete: false,
                    });
                    Ok(())
                }
                _ => Err(Abort::InvalidCommand),
            },
            (ClientPhase::Segment { toggle }, None) => {
                if command >> 5 != 0 {
                    return Err(Abort::InvalidCommand);
                }
                if (command & 0x10 != 0) != toggle {
                    return Err(Abort::ToggleNotAlternated);
                }
                let unused = usize::from((command >> 1) & 0x07);
                self.buffer
                    .extend_from_slice(response.get(1..8 - unused).unwrap_or(&[]));
                if command & 0x01 != 0 {
                    let data = core::mem::take(&mut self.buffer);
                    self.finish(Ok(data));
                } else {
                    self.send(node, [0x60 | (u8::from(!toggle) << 4), 0, 0, 0, 0, 0, 0, 0]);
                    self.set_phase(ClientPhase::Segment { toggle: !toggle });
                }
                Ok(())
            }
            (
                ClientPhase::UploadBlock {
                    expected,
                    crc,
                    size,
                    complete: false,
                },
                None,
            ) => {
                let sequence = command & 0x7F;
                let last = command & 0x80 != 0;
                let in_order = sequence == expected;
                if in_order {
                    self.buffer
                        .extend_from_slice(response.get(1..).unwrap_or(&[]));
                }
                if sequence == MAX_BLOCK || (last && in_order) {
                    let acked = if in_order { sequence } else { expected - 1 };
                    self.send(node, [0xA2, acked, MAX_BLOCK, 0, 0, 0, 0, 0]);
                    self.set_phase(ClientPhase::UploadBlock {
                        expected: 1,
                        crc,
                        size,
                        complete: last && in_order,
                    });
                } else if in_order {
                    self.set_phase(ClientPhase::UploadBlock {
                        expected: expected + 1,
                        crc,
                        size,
                        complete: false,
                    });
                } else if last {
                    // The block ended with gaps: acknowledge what arrived in order.
                    self.send(node, [0xA2, expected - 1, MAX_BLOCK, 0, 0, 0, 0, 0]);
                    self.set_phase(ClientPhase::UploadBlock {
                        expected: 1,
                        crc,
                        size,
                        complete: false,
                    });
                }
                Ok(())
            }
            (
                ClientPhase::UploadBlock {
                    crc,
                    size,
                    complete: true,
                    ..
                },
                None,
            ) => {
                if command & 0xE3 != 0xC1 {
                    return Err(Abort::InvalidCommand);
                }
                let unused = usize::from((command >> 2) & 0x07);
                let len = self.buffer.len().saturating_sub(unused);
                self.buffer.truncate(len);
                if size.is_some_and(|size| size != len) {
                    return Err(Abort::LengthMismatch);
                }
                if crc && crc16(0, &self.buffer) != u16::from_le_bytes([response[1], response[2]]) {
                    return Err(Abort::CrcError);
                }
                self.send(node, [0xA1, 0, 0, 0, 0, 0, 0, 0]);
                let data = core::mem::take(&mut self.buffer);
                self.finish(Ok(data));
                Ok(())
            }
            (ClientPhase::Initiated, Some(data)) => match (command >> 5, request.mode) {
                (3, mode) if mode != TransferMode::Block => {
                    Self::check_target(request, &response)?;
                    let expedited =
                        request.mode == TransferMode::Auto && (1..=4).contains(&data.len());
                    if expedited {
                        self.finish(Ok(Vec::new()));
                    } else {
                        self.send_download_segment(node, data, false);
                    }
                    Ok(())
                }
                (5, TransferMode::Block) if command & 0x03 == 0 => {
                    Self::check_target(request, &response)?;
                    let block_size = response[4];
                    if block_size == 0 || block_size > MAX_BLOCK {
                        return Err(Abort::InvalidBlockSize);
                    }
                    let crc = command & 0x04 != 0;
                    let sent = self.send_download_block(node, data, 0, block_size);
                    self.set_phase(ClientPhase::DownloadBlock {
                        block_start: 0,
                        sent,
                        block_size,
                        crc,
                    });
                    Ok(())
                }
                _ => Err(Abort::InvalidCommand),
            },
            (ClientPhase::Segment { toggle }, Some(data)) => {
                if command & 0xE0 != 0x20 {
                    return Err(Abort::InvalidCommand);
                }
                if (command & 0x10 != 0) != toggle {
                    return Err(Abort::ToggleNotAlternated);
                }
                if self.offset >= data.len() {
                    self.finish(Ok(Vec::new()));
                } else {
                    self.send_download_segment(node, data, !toggle);
                }
                Ok(())
            }
            (
                ClientPhase::DownloadBlock {
                    block_start,
                    sent,
                    crc,
                    ..
                },
                Some(data),
            ) => {
                if command != 0xA2 {
                    return Err(Abort::InvalidCommand);
                }
                let acked = response[1];
                let block_size = response[2];
                if acked > sent {
                    return Err(Abort::InvalidSequence);
                }
                if block_size == 0 || block_size > MAX_BLOCK {
                    return Err(Abort::InvalidBlockSize);
                }
                let next = block_start + 7 * usize::from(acked);
                if next >= data.len() && acked == sent {
                    let check = if crc { crc16(0, data) } else { 0 };
                    let [lo, hi] = check.to_le_bytes();
                    self.send(
                        node,
                        [
                            0xC1 | (unused_in_last(data.len()) << 2),
                            lo,
                            hi,
                            0,
                            0,
                            0,
                            0,
                            0,
                        ],
                    );
                    self.set_phase(ClientPhase::DownloadBlockEnd);
                } else {
                    let sent = self.send_download_block(node, data, next, block_size);
                    self.set_phase(ClientPhase::DownloadBlock {
                        block_start: next,
                        sent,
                        block_size,
                        crc,
                    });
                }
                Ok(())
            }
            (ClientPhase::DownloadBlockEnd, Some(_)) => {
                if command & 0xE3 != 0xA1 {
                    return Err(Abort::InvalidCommand);
                }
                self.finish(Ok(Vec::new()));
                Ok(())
            }
            (ClientPhase::DownloadBlock { .. } | ClientPhase::DownloadBlockEnd, None)
            | (ClientPhase::UploadBlock { .. }, Some(_)) => Err(Abort::General),
        }
    }

    fn send_download_segment(&mut self, node: u8, data: &[u8], toggle: bool) {
        let (bytes, n) = segment_at(data, self.offset);
        self.offset += n;
        let last = self.offset >= data.len();
        let unused = u8::try_from(7 - n).unwrap_or(0);
        self.send(
            node,
            segment_frame(
                (u8::from(toggle) << 4) | (unused << 1) | u8::from(last),
                bytes,
            ),
        );
        self.set_phase(ClientPhase::Segment { toggle });
    }

    fn send_download_block(&mut self, node: u8, data: &[u8], start: usize, block_size: u8) -> u8 {
        let mut sent = 0u8;
        let mut offset = start;
        while sent < block_size {
            let (bytes, n) = segment_at(data, offset);
            offset += n;
            sent += 1;
            let last = offset >= data.len();
            self.send(
                node,
                segment_frame(sent | if last { 0x80 } else { 0 }, bytes),
            );
            if last {
                break;
            }
        }
        sent
    }

    /// Start queued requests, time out silent servers, send what is due.
    pub fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Frame)) {
        if self.deadline.is_some_and(|deadline| now >= deadline) {
            self.fail(Abort::Timeout, SdoError::Timeout);
        }
        if self.current.is_none() {
            self.start(now);
        }
        while let Some(frame) = self.outbox.pop() {
            out(frame);
        }
    }

    /// When the transfer under way times out, or now if work waits.
    pub fn next_deadline(&self) -> Option<Timestamp> {
        if !self.outbox.is_empty() || (self.current.is_none() && !self.queue.is_empty()) {
            return Some(Timestamp::ZERO);
        }
        self.deadline
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::od::{Access, DataType, Entry, ObjectDictionary};

    struct Dictionary(ObjectDictionary);

    impl Objects for Dictionary {
        fn upload(&mut self, index: u16, sub: u8, into: &mut Vec<u8>) -> Result<(), Abort> {
            let value = self.0.read(index, sub)?;
            if value.len() > into.capacity() {
                return Err(Abort::OutOfMemory);
            }
            into.clear();
            into.extend_from_slice(value);
            Ok(())
        }
        fn check_download(&self, index: u16, sub: u8, _size: Option<usize>) -> Result<(), Abort> {
            let entry = self.0.entry(index, sub)?;
            if entry.access.writable() {
                Ok(())
            } else {
                Err(Abort::WriteReadOnly)
            }
        }
        fn download(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<(), Abort> {
            self.0.check_write(index, sub, data)?;
            self.0.set(index, sub, data)
        }
    }

    fn dictionary() -> Dictionary {
        let mut od = ObjectDictionary::new();
        od.add_var(
            0x1008,
            Entry::new(0, "Name", DataType::VisibleString, Access::ReadWrite)
                .with_default(b"bywire drive"),
        );
        od.add_var(
            0x2000,
            Entry::new(0, "Command", DataType::I32, Access::ReadWrite),
        );
        od.add_var(
            0x2001,
            Entry::new(0, "Blob", DataType::Domain, Access::ReadWrite).with_default(&[0; 1000]),
        );
        od.add_var(
            0x1000,
            Entry::new(0, "Device type", DataType::U32, Access::ReadOnly),
        );
        Dictionary(od)
    }

    /// Client and server wired back to back, frames passed until both are quiet.
    fn exchange(
        client: &mut SdoClient,
        server: &mut SdoServer,
        objects: &mut Dictionary,
        drop_frame: &mut dyn FnMut(&Frame) -> bool,
    ) {
        let now = Timestamp::from_millis(1);
        for _ in 0..10_000 {
            let mut to_server = Vec::new();
            client.poll(now, &mut |f| to_server.push(f));
            let mut to_client = Vec::new();
            for frame in &to_server {
                if !drop_frame(frame) {
                    server.on_frame(now, frame, objects);
                }
            }
            server.poll(now, &mut |f| to_client.push(f));
            for frame in &to_client {
                if !drop_frame(frame) {
                    client.on_frame(now, frame);
                }
            }
            if to_server.is_empty() && to_client.is_empty() && client.is_idle() {
                return;
            }
        }
        panic!("the exchange did not settle");
    }

    #[test]
    fn every_transfer_mode_moves_data_both_ways() {
        let data: Vec<u8> = (0..1000u32).map(|i| (i * 7 % 251) as u8).collect();
        for mode in [
            TransferMode::Auto,
            TransferMode::Segmented,
            TransferMode::Block,
        ] {
            let mut objects = dictionary();
            let mut server = SdoServer::new(5, 1024);
            let mut client = SdoClient::new(4, Duration::from_millis(500));
            client.download(5, 0x2001, 0, &data, mode).unwrap();
            client
                .download(5, 0x2000, 0, &(-700i32).to_le_bytes(), mode)
                .unwrap();
            client.upload(5, 0x2001, 0, mode).unwrap();
            client.upload(5, 0x1008, 0, mode).unwrap();
            exchange(&mut client, &mut server, &mut objects, &mut |_| false);
            let outcomes: Vec<_> = core::iter::from_fn(|| client.take_outcome()).collect();
            assert_eq!(outcomes.len(), 4, "{mode:?}");
            assert_eq!(outcomes[0].result, Ok(Vec::new()), "{mode:?}");
            assert_eq!(outcomes[1].result, Ok(Vec::new()), "{mode:?}");
            assert_eq!(objects.0.get_signed(0x2000, 0), Some(-700));
            assert_eq!(outcomes[2].result.as_deref(), Ok(&data[..]), "{mode:?}");
            assert_eq!(
                outcomes[3].result.as_deref(),
                Ok(&b"bywire drive"[..]),
                "{mode:?}"
            );
            assert!(server.is_idle());
        }
    }

    #[test]
    fn lost_block_segments_are_repeated() {
        let data: Vec<u8> = (0..900u32).map(|i| (i % 253) as u8).collect();
        let mut objects = dictionary();
        let mut server = SdoServer::new(5, 1024);
        let mut client = SdoClient::new(4, Duration::from_millis(500));
        client
            .download(5, 0x2001, 0, &data, TransferMode::Block)
            .unwrap();
        client.upload(5, 0x2001, 0, TransferMode::Block).unwrap();
        // Lose segment 40 once in each direction: the receiver acknowledges 39 and the
        // sender repeats from 40.
        let mut lost = Vec::new();
        exchange(&mut client, &mut server, &mut objects, &mut |frame| {
            let id = cob_id(frame).unwrap();
            let lose = frame.data()[0] == 40 && !lost.contains(&id);
            if lose {
                lost.push(id);
            }
            lose
        });
        assert_eq!(lost.len(), 2, "a segment was lost each way");
        let download = client.take_outcome().unwrap();
        assert_eq!(download.result, Ok(Vec::new()));
        assert_eq!(
            client.take_outcome().unwrap().result.as_deref(),
            Ok(&data[..])
        );
    }

    #[test]
    fn refusals_come_back_as_abort_codes() {
        let mut objects = dictionary();
        let mut server = SdoServer::new(5, 1024);
        let mut client = SdoClient::new(8, Duration::from_millis(500));
        client
            .download(5, 0x1000, 0, &[1, 2, 3, 4], TransferMode::Auto)
            .unwrap();
        client
            .download(5, 0x2000, 0, &[1, 2], TransferMode::Auto)
            .unwrap();
        client.upload(5, 0x3000, 0, TransferMode::Auto).unwrap();
        client.upload(5, 0x2000, 7, TransferMode::Block).unwrap();
        client
            .download(5, 0x1000, 0, &[0; 20], TransferMode::Block)
            .unwrap();
        client
            .download(5, 0x2001, 0, &[0; 2000], TransferMode::Segmented)
            .unwrap();
        exchange(&mut client, &mut server, &mut objects, &mut |_| false);
        let results: Vec<_> = core::iter::from_fn(|| client.take_outcome())
            .map(|o| o.result)
            .collect();
        assert_eq!(
            results,
            [
                Err(SdoError::Aborted(Abort::WriteReadOnly)),
                Err(SdoError::Aborted(Abort::LengthTooLow)),
                Err(SdoError::Aborted(Abort::NoObject)),
                Err(SdoError::Aborted(Abort::NoSubindex)),
                Err(SdoError::Aborted(Abort::WriteReadOnly)),
                Err(SdoError::Aborted(Abort::OutOfMemory)),
            ]
        );
    }

    #[test]
    fn a_silent_server_times_out_and_the_queue_is_bounded() {
        let mut client = SdoClient::new(1, Duration::from_millis(300));
        client.upload(5, 0x1000, 0, TransferMode::Auto).unwrap();
        assert_eq!(
            client.upload(5, 0x1000, 0, TransferMode::Auto),
            Err(QueueFull)
        );
        let mut sent = Vec::new();
        client.poll(Timestamp::from_millis(0), &mut |f| sent.push(f));
        assert_eq!(sent.len(), 1);
        assert_eq!(client.next_deadline(), Some(Timestamp::from_millis(300)));
        client.poll(Timestamp::from_millis(300), &mut |f| sent.push(f));
        assert_eq!(
            client.take_outcome().unwrap().result,
            Err(SdoError::Timeout)
        );
        assert_eq!(sent[1].data(), abort_payload(0x1000, 0, Abort::Timeout));
    }

    #[test]
    fn a_server_left_waiting_aborts_with_timeout() {
        let mut objects = dictionary();
        let mut server = SdoServer::new(5, 1024);
        let initiate = classic(0x605, &[0x40, 0x08, 0x10, 0, 0, 0, 0, 0]);
        server.on_frame(Timestamp::ZERO, &initiate, &mut objects);
        let mut sent = Vec::new();
        server.poll(Timestamp::ZERO, &mut |f| sent.push(f));
        assert_eq!(
            sent[0].data()[0],
            0x41,
            "segmented upload of a 12-byte string"
        );
        server.poll(
            SERVER_TIMEOUT
                .as_nanos()
                .try_into()
                .map(Timestamp::from_nanos)
                .unwrap(),
            &mut |f| sent.push(f),
        );
        assert_eq!(sent[1].data(), abort_payload(0x1008, 0, Abort::Timeout));
        assert!(server.is_idle());
    }

    #[test]
    fn crc16_matches_the_xmodem_check_value() {
        assert_eq!(crc16(0, b"123456789"), 0x31C3);
    }
}
