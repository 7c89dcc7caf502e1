//! The SDO client a master uses: a queue of requests to any node, each answered by an
//! outcome, with timeouts.

use super::frames::{
    abort_payload, crc16, index_of, segment_at, segment_frame, u32_at4, unused_in_last, with_index,
};
use super::{MAX_BLOCK, OUTBOX};
use alloc::collections::VecDeque;
use alloc::vec::Vec;
use core::time::Duration;

use bywire_core::frame::Frame;
use bywire_core::time::Timestamp;

use crate::abort::Abort;
use crate::nmt::{classic, cob_id};
use crate::queue::EventQueue;

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
#[non_exhaustive]
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

    /// The server's `response` to the transfer in `phase`: the one transition function of a
    /// transfer, a method per phase and direction.
    fn advance(
        &mut self,
        request: &Request,
        phase: ClientPhase,
        response: [u8; 8],
    ) -> Result<(), Abort> {
        let node = request.node;
        match (phase, &request.data) {
            (ClientPhase::Initiated, None) => self.upload_initiated(request, response),
            (ClientPhase::Segment { toggle }, None) => self.upload_segment(node, toggle, response),
            (
                ClientPhase::UploadBlock {
                    expected,
                    crc,
                    size,
                    complete: false,
                },
                None,
            ) => {
                self.upload_block_segment(node, expected, (crc, size), response);
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
            ) => self.upload_block_end(node, crc, size, response),
            (ClientPhase::Initiated, Some(data)) => {
                self.download_initiated(request, data, response)
            }
            (ClientPhase::Segment { toggle }, Some(data)) => {
                self.download_segment(node, data, toggle, response)
            }
            (
                ClientPhase::DownloadBlock {
                    block_start,
                    sent,
                    crc,
                    ..
                },
                Some(data),
            ) => self.download_block_acknowledged(node, data, (block_start, sent, crc), response),
            (ClientPhase::DownloadBlockEnd, Some(_)) => {
                if response[0] & 0xE3 != 0xA1 {
                    return Err(Abort::InvalidCommand);
                }
                self.finish(Ok(Vec::new()));
                Ok(())
            }
            (ClientPhase::DownloadBlock { .. } | ClientPhase::DownloadBlockEnd, None)
            | (ClientPhase::UploadBlock { .. }, Some(_)) => Err(Abort::General),
        }
    }

    /// An upload's initiate response: expedited data, the first segment asked for, or a
    /// block upload started.
    fn upload_initiated(&mut self, request: &Request, response: [u8; 8]) -> Result<(), Abort> {
        let (command, node) = (response[0], request.node);
        match command >> 5 {
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
        }
    }

    /// An upload's segment.
    fn upload_segment(&mut self, node: u8, toggle: bool, response: [u8; 8]) -> Result<(), Abort> {
        let command = response[0];
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

    /// A segment of a block upload: acknowledged at the block's end or at a gap.
    fn upload_block_segment(
        &mut self,
        node: u8,
        expected: u8,
        (crc, size): (bool, Option<usize>),
        response: [u8; 8],
    ) {
        let command = response[0];
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
    }

    /// A block upload's end: its length and CRC checked.
    fn upload_block_end(
        &mut self,
        node: u8,
        crc: bool,
        size: Option<usize>,
        response: [u8; 8],
    ) -> Result<(), Abort> {
        let command = response[0];
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

    /// A download's initiate response: done (expedited), the first segment, or the first
    /// block.
    fn download_initiated(
        &mut self,
        request: &Request,
        data: &[u8],
        response: [u8; 8],
    ) -> Result<(), Abort> {
        let (command, node) = (response[0], request.node);
        match (command >> 5, request.mode) {
            (3, mode) if mode != TransferMode::Block => {
                Self::check_target(request, &response)?;
                let expedited = request.mode == TransferMode::Auto && (1..=4).contains(&data.len());
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
        }
    }

    /// A download segment's response.
    fn download_segment(
        &mut self,
        node: u8,
        data: &[u8],
        toggle: bool,
        response: [u8; 8],
    ) -> Result<(), Abort> {
        let command = response[0];
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

    /// A downloaded block's acknowledgement: the next block, or the end.
    fn download_block_acknowledged(
        &mut self,
        node: u8,
        data: &[u8],
        (block_start, sent, crc): (usize, u8, bool),
        response: [u8; 8],
    ) -> Result<(), Abort> {
        let command = response[0];
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
