//! The SDO server a device runs: expedited, segmented and block transfers against its
//! objects, one transfer at a time, buffers sized when it is made.

use super::frames::{
    abort_payload, crc16, index_of, segment_at, segment_frame, u32_at4, unused_in_last, with_index,
};
use super::{MAX_BLOCK, OUTBOX, SERVER_TIMEOUT};
use alloc::vec::Vec;

use bywire_core::frame::Frame;
use bywire_core::time::Timestamp;

use crate::abort::Abort;
use crate::nmt::{classic, cob_id};
use crate::queue::EventQueue;

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
