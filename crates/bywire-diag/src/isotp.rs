//! ISO-TP (ISO 15765-2) as a sans-IO node: one channel between two addresses, sending and
//! receiving at once.
//!
//! - Frames: single (classic up to 7 bytes; CAN FD up to 62 with the escape form), first
//!   (12-bit length up to 4095, the 32-bit escape beyond), consecutive, flow control.
//! - Flow control both ways: the receiver's block size and STmin (milliseconds, and the
//!   100–900 µs codes) are honoured when sending and offered when receiving; WAIT frames up to
//!   `max_wait_frames`; OVERFLOW when a message is larger than the receive buffer.
//! - Timers, from the time each call is given: N_Bs (waiting for flow control) and N_Cr
//!   (waiting for a consecutive frame). N_As/N_Ar (a frame's own transmission) belong to the
//!   controller: a node hands its frames to the runner and has no confirmation to time.
//! - Addressing: normal (the identifiers alone; normal fixed 0x18DA/0x18DB for 29 bits is a
//!   choice of identifiers, [`Addressing::normal_fixed`]), extended (a target address byte
//!   first) and mixed (an address extension byte first); padding to full frames, or none.
//!
//! Errors carry the standard's names (`N_TIMEOUT_Bs`, `N_WRONG_SN`, …). Nothing from the bus
//! can make it panic or grow beyond `max_message`; every loop is bounded by a frame's length.

use alloc::collections::VecDeque;
use alloc::vec::Vec;
use core::fmt;
use core::time::Duration;

use bywire_core::node::Port;
use bywire_core::{Frame, Id, Timestamp};

/// The largest message the 32-bit first frame can announce that this node takes (a buffer of
/// this size is never made: `max_message` bounds what is accepted).
pub const MAX_ESCAPE_LENGTH: usize = u32::MAX as usize;

/// Separation time between consecutive frames, as flow control encodes it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum StMin {
    /// 0–127 ms.
    Millis(u8),
    /// 100–900 µs (codes 0xF1–0xF9).
    Micros(u16),
}

impl StMin {
    /// The byte of a flow-control frame. Out-of-range values are sent as the nearest code.
    pub fn to_byte(self) -> u8 {
        match self {
            StMin::Millis(ms) => ms.min(0x7F),
            StMin::Micros(us) => {
                let hundreds = u8::try_from((us / 100).clamp(1, 9)).unwrap_or(9);
                0xF0 + hundreds
            }
        }
    }

    /// From a received byte; reserved codes mean 127 ms, as the standard asks a sender to
    /// take them.
    pub fn from_byte(byte: u8) -> StMin {
        match byte {
            0x00..=0x7F => StMin::Millis(byte),
            0xF1..=0xF9 => StMin::Micros(u16::from(byte - 0xF0) * 100),
            _ => StMin::Millis(0x7F),
        }
    }

    /// As a duration.
    pub fn duration(self) -> Duration {
        match self {
            StMin::Millis(ms) => Duration::from_millis(u64::from(ms.min(0x7F))),
            StMin::Micros(us) => Duration::from_micros(u64::from(us.clamp(100, 900))),
        }
    }
}

/// How the channel's frames are addressed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Addressing {
    /// The identifiers alone.
    Normal,
    /// A target address byte first: `target` in what is sent, `source` expected in what is
    /// received.
    Extended {
        /// The byte sent.
        target: u8,
        /// The byte received frames carry.
        source: u8,
    },
    /// An address extension byte first, the same both ways.
    Mixed {
        /// The address extension.
        extension: u8,
    },
}

impl Addressing {
    /// Normal fixed addressing (29-bit, SAE J1939-style): physical 0x18DA_TA_SA, functional
    /// 0x18DB_TA_SA; (transmit identifier, receive identifier) for a tester `source` talking to
    /// `target`.
    pub fn normal_fixed(target: u8, source: u8, functional: bool) -> (Id, Id) {
        let base = if functional { 0x18DB_0000 } else { 0x18DA_0000 };
        let tx = base | (u32::from(target) << 8) | u32::from(source);
        let rx = 0x18DA_0000 | (u32::from(source) << 8) | u32::from(target);
        (
            Id::extended(tx).unwrap_or(Id::Extended(bywire_core::ExtendedId::ZERO)),
            Id::extended(rx).unwrap_or(Id::Extended(bywire_core::ExtendedId::ZERO)),
        )
    }

    fn prefix(self) -> Option<u8> {
        match self {
            Addressing::Normal => None,
            Addressing::Extended { target, .. } => Some(target),
            Addressing::Mixed { extension } => Some(extension),
        }
    }

    fn expected(self) -> Option<u8> {
        match self {
            Addressing::Normal => None,
            Addressing::Extended { source, .. } => Some(source),
            Addressing::Mixed { extension } => Some(extension),
        }
    }
}

/// A channel's settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IsoTpConfig {
    /// The identifier frames are sent with.
    pub tx_id: Id,
    /// The identifier frames are received on.
    pub rx_id: Id,
    /// Addressing.
    pub addressing: Addressing,
    /// CAN FD frames (with `tx_dl` bytes) instead of classic ones.
    pub fd: bool,
    /// With `fd`: the bit-rate switch.
    pub brs: bool,
    /// With `fd`: the frame length used (8, 12, 16, 20, 24, 32, 48 or 64).
    pub tx_dl: usize,
    /// Pad every frame to its full length with this byte (`None`: the shortest frames; CAN FD
    /// lengths without a code are always padded, with 0xCC).
    pub padding: Option<u8>,
    /// The block size offered when receiving (0: no further flow control).
    pub block_size: u8,
    /// The separation time asked for when receiving.
    pub st_min: StMin,
    /// WAIT frames accepted in a row before the transfer is given up (N_WFT_OVRN).
    pub max_wait_frames: u8,
    /// Longest wait for a flow-control frame (N_Bs).
    pub n_bs: Duration,
    /// Longest wait for a consecutive frame (N_Cr).
    pub n_cr: Duration,
    /// The largest message received (a longer one is refused with OVERFLOW).
    pub max_message: usize,
    /// Separation time used regardless of what the receiver asks (`None`: the receiver's).
    pub st_min_override: Option<Duration>,
}

impl IsoTpConfig {
    /// Classic frames between `tx_id` and `rx_id`, normal addressing, no padding, BS 0,
    /// STmin 0, N_Bs and N_Cr 1 s, messages up to 4095 bytes.
    pub fn new(tx_id: Id, rx_id: Id) -> Self {
        IsoTpConfig {
            tx_id,
            rx_id,
            addressing: Addressing::Normal,
            fd: false,
            brs: false,
            tx_dl: 8,
            padding: None,
            block_size: 0,
            st_min: StMin::Millis(0),
            max_wait_frames: 10,
            n_bs: Duration::from_millis(1000),
            n_cr: Duration::from_millis(1000),
            max_message: 4095,
            st_min_override: None,
        }
    }

    /// The frame length used: 8 for classic frames, `tx_dl` (a valid FD length) for FD.
    fn frame_len(&self) -> usize {
        if self.fd {
            bywire_core::frame::Dlc::fd_covering(self.tx_dl.clamp(8, 64))
                .map_or(64, bywire_core::frame::Dlc::fd_len)
        } else {
            8
        }
    }

    fn prefix_len(&self) -> usize {
        usize::from(self.addressing.prefix().is_some())
    }
}

/// What went wrong, by the standard's names.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum IsoTpError {
    /// N_TIMEOUT_Bs: no flow control in time.
    TimeoutBs,
    /// N_TIMEOUT_Cr: no consecutive frame in time.
    TimeoutCr,
    /// N_WRONG_SN: a consecutive frame out of sequence.
    WrongSequenceNumber {
        /// The one expected.
        expected: u8,
        /// The one received.
        received: u8,
    },
    /// N_INVALID_FS: a flow status that is not CTS, WAIT or OVFLW.
    InvalidFlowStatus(u8),
    /// N_UNEXP_PDU: a frame that does not fit the transfer (a new first or single frame
    /// during reception aborts the old one; the new one is taken).
    UnexpectedPdu,
    /// N_WFT_OVRN: more WAIT frames than allowed.
    WaitFrameOverrun,
    /// N_BUFFER_OVFLW: the receiver cannot take the message (it sent OVERFLOW, or, received,
    /// it is longer than `max_message`).
    BufferOverflow,
    /// A frame whose PCI is malformed (a length that does not fit the frame, a reserved type).
    Malformed,
}

impl fmt::Display for IsoTpError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            IsoTpError::TimeoutBs => f.write_str("N_TIMEOUT_Bs: no flow control frame in time"),
            IsoTpError::TimeoutCr => f.write_str("N_TIMEOUT_Cr: no consecutive frame in time"),
            IsoTpError::WrongSequenceNumber { expected, received } => write!(
                f,
                "N_WRONG_SN: consecutive frame {received} where {expected} was due"
            ),
            IsoTpError::InvalidFlowStatus(fs) => {
                write!(
                    f,
                    "N_INVALID_FS: flow status {fs} is not CTS, WAIT or OVFLW"
                )
            }
            IsoTpError::UnexpectedPdu => f.write_str("N_UNEXP_PDU: a frame out of its place"),
            IsoTpError::WaitFrameOverrun => {
                f.write_str("N_WFT_OVRN: more WAIT flow control frames than allowed")
            }
            IsoTpError::BufferOverflow => {
                f.write_str("N_BUFFER_OVFLW: the message is larger than the receiver takes")
            }
            IsoTpError::Malformed => f.write_str("a malformed ISO-TP frame"),
        }
    }
}

/// What the channel tells its user.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum IsoTpEvent {
    /// A whole message arrived.
    Received(Vec<u8>),
    /// The message given to [`IsoTp::send`] is sent.
    Sent,
    /// A transfer failed; sending (`sending: true`) or receiving.
    Failed {
        /// Whose transfer.
        sending: bool,
        /// Why.
        error: IsoTpError,
    },
}

/// Why a message cannot be sent now.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SendError {
    /// A message is still being sent.
    Busy,
    /// Empty, or longer than ISO-TP carries.
    Length(usize),
}

impl fmt::Display for SendError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SendError::Busy => f.write_str("a message is still being sent"),
            SendError::Length(n) => write!(f, "{n} bytes cannot be sent (1 to 4294967295)"),
        }
    }
}

#[derive(Debug, Clone, PartialEq, Eq)]
enum Tx {
    Idle,
    /// A single or first frame is due.
    Start,
    /// Waiting for flow control until `deadline`; `waits` WAIT frames so far; the next
    /// consecutive frame's sequence number.
    AwaitFlow {
        deadline: Timestamp,
        waits: u8,
        sequence: u8,
    },
    /// Sending consecutive frames.
    Consecutive {
        next_at: Timestamp,
        sequence: u8,
        /// Frames left in the block (`None`: no limit).
        block_left: Option<u8>,
        separation: Duration,
    },
}

#[derive(Debug, Clone, PartialEq, Eq)]
enum Rx {
    Idle,
    Receiving {
        length: usize,
        sequence: u8,
        block_left: Option<u8>,
        deadline: Timestamp,
    },
}

/// Flow statuses.
const CTS: u8 = 0;
const WAIT: u8 = 1;
const OVFLW: u8 = 2;

/// An ISO-TP channel (one node on one port).
#[derive(Debug, Clone)]
pub struct IsoTp {
    config: IsoTpConfig,
    port: Port,
    tx: Tx,
    tx_data: Vec<u8>,
    tx_offset: usize,
    rx: Rx,
    rx_data: Vec<u8>,
    /// Flow control frames due (flow status).
    flow_due: VecDeque<u8>,
    events: VecDeque<IsoTpEvent>,
}

impl IsoTp {
    /// A channel with `config` on the node's main port.
    pub fn new(config: IsoTpConfig) -> Self {
        IsoTp {
            config,
            port: Port::MAIN,
            tx: Tx::Idle,
            tx_data: Vec::new(),
            tx_offset: 0,
            rx: Rx::Idle,
            rx_data: Vec::new(),
            flow_due: VecDeque::new(),
            events: VecDeque::new(),
        }
    }

    /// The settings.
    pub fn config(&self) -> &IsoTpConfig {
        &self.config
    }

    /// Whether a message is being sent.
    pub fn sending(&self) -> bool {
        self.tx != Tx::Idle
    }

    /// Send `data` (from the next poll).
    pub fn send(&mut self, data: &[u8]) -> Result<(), SendError> {
        if self.sending() {
            return Err(SendError::Busy);
        }
        if data.is_empty() || data.len() > MAX_ESCAPE_LENGTH {
            return Err(SendError::Length(data.len()));
        }
        self.tx_data.clear();
        self.tx_data.extend_from_slice(data);
        self.tx_offset = 0;
        self.tx = Tx::Start;
        Ok(())
    }

    /// The next event.
    pub fn next_event(&mut self) -> Option<IsoTpEvent> {
        self.events.pop_front()
    }

    fn fail(&mut self, sending: bool, error: IsoTpError) {
        if sending {
            self.tx = Tx::Idle;
        } else {
            self.rx = Rx::Idle;
            self.rx_data.clear();
        }
        self.events.push_back(IsoTpEvent::Failed { sending, error });
    }

    /// A frame with `payload` after the addressing byte, padded as configured.
    fn frame(&self, payload: &[u8]) -> Option<Frame> {
        let mut data = Vec::with_capacity(64);
        data.extend(self.config.addressing.prefix());
        data.extend_from_slice(payload);
        let full = self.config.frame_len();
        let len = match self.config.padding {
            Some(_) => full,
            None if self.config.fd && data.len() > 8 => {
                bywire_core::frame::Dlc::fd_covering(data.len()).map_or(full, |d| d.fd_len())
            }
            None => data.len(),
        };
        data.resize(len.max(data.len()), self.config.padding.unwrap_or(0xCC));
        if self.config.fd {
            Frame::fd(self.config.tx_id, &data, self.config.brs, false).ok()
        } else {
            Frame::classic(self.config.tx_id, &data).ok()
        }
    }

    /// The payload room of one frame after the addressing byte.
    fn room(&self) -> usize {
        self.config.frame_len() - self.config.prefix_len()
    }

    /// Take a frame from the bus.
    pub fn on_frame(&mut self, now: Timestamp, frame: &Frame) {
        if frame.id() != Some(self.config.rx_id) || frame.is_remote() || frame.is_error() {
            return;
        }
        let data = frame.data();
        let (data, expected) = match self.config.addressing.expected() {
            Some(byte) => match data.split_first() {
                Some((first, rest)) if *first == byte => (rest, true),
                _ => (data, false),
            },
            None => (data, true),
        };
        if !expected {
            return;
        }
        let Some(&pci) = data.first() else { return };
        match pci >> 4 {
            0 => self.on_single(data, frame.is_fd()),
            1 => self.on_first(now, data),
            2 => self.on_consecutive(now, pci & 0x0F, data.get(1..).unwrap_or(&[])),
            3 => self.on_flow(now, data),
            // Reserved PCI types are ignored, as the standard asks.
            _ => {}
        }
    }

    fn on_single(&mut self, data: &[u8], fd: bool) {
        let pci = data.first().copied().unwrap_or(0);
        let (length, start) = if pci & 0x0F == 0 && fd {
            // The CAN FD escape: the length in the second byte.
            (usize::from(data.get(1).copied().unwrap_or(0)), 2)
        } else {
            (usize::from(pci & 0x0F), 1)
        };
        let Some(payload) = data.get(start..start + length).filter(|_| length > 0) else {
            return;
        };
        if self.rx != Rx::Idle {
            self.events.push_back(IsoTpEvent::Failed {
                sending: false,
                error: IsoTpError::UnexpectedPdu,
            });
            self.rx = Rx::Idle;
        }
        self.events
            .push_back(IsoTpEvent::Received(payload.to_vec()));
    }

    fn on_first(&mut self, now: Timestamp, data: &[u8]) {
        let short = (usize::from(data.first().copied().unwrap_or(0) & 0x0F) << 8)
            | usize::from(data.get(1).copied().unwrap_or(0));
        let (length, start) = if short == 0 {
            let Some(bytes) = data.get(2..6) else { return };
            let mut be = [0u8; 4];
            be.copy_from_slice(bytes);
            (
                usize::try_from(u32::from_be_bytes(be)).unwrap_or(usize::MAX),
                6,
            )
        } else {
            (short, 2)
        };
        let Some(payload) = data.get(start..) else {
            return;
        };
        // A first frame is only for what a single frame cannot carry.
        if length <= payload.len() {
            return;
        }
        if self.rx != Rx::Idle {
            self.events.push_back(IsoTpEvent::Failed {
                sending: false,
                error: IsoTpError::UnexpectedPdu,
            });
        }
        if length > self.config.max_message {
            self.rx = Rx::Idle;
            self.rx_data.clear();
            self.flow_due.push_back(OVFLW);
            self.events.push_back(IsoTpEvent::Failed {
                sending: false,
                error: IsoTpError::BufferOverflow,
            });
            return;
        }
        self.rx_data.clear();
        self.rx_data.reserve(length);
        self.rx_data.extend_from_slice(payload);
        self.rx = Rx::Receiving {
            length,
            sequence: 1,
            block_left: (self.config.block_size > 0).then_some(self.config.block_size),
            deadline: now.saturating_add(self.config.n_cr),
        };
        self.flow_due.push_back(CTS);
    }

    fn on_consecutive(&mut self, now: Timestamp, sequence: u8, payload: &[u8]) {
        let Rx::Receiving {
            length,
            sequence: expected,
            block_left,
            ..
        } = self.rx
        else {
            return;
        };
        if sequence != expected {
            return self.fail(
                false,
                IsoTpError::WrongSequenceNumber {
                    expected,
                    received: sequence,
                },
            );
        }
        let wanted = (length - self.rx_data.len()).min(payload.len());
        self.rx_data
            .extend_from_slice(payload.get(..wanted).unwrap_or(payload));
        if self.rx_data.len() >= length {
            self.rx = Rx::Idle;
            let message = core::mem::take(&mut self.rx_data);
            self.events.push_back(IsoTpEvent::Received(message));
            return;
        }
        let block_left = match block_left {
            Some(1) => {
                self.flow_due.push_back(CTS);
                (self.config.block_size > 0).then_some(self.config.block_size)
            }
            Some(n) => Some(n - 1),
            None => None,
        };
        self.rx = Rx::Receiving {
            length,
            sequence: (expected + 1) & 0x0F,
            block_left,
            deadline: now.saturating_add(self.config.n_cr),
        };
    }

    fn on_flow(&mut self, now: Timestamp, data: &[u8]) {
        let Tx::AwaitFlow {
            waits, sequence, ..
        } = self.tx
        else {
            // Flow control out of its place is ignored (the standard's N_UNEXP_PDU for FC).
            return;
        };
        let status = data.first().copied().unwrap_or(0) & 0x0F;
        let (Some(&block_size), Some(&st_min)) = (data.get(1), data.get(2)) else {
            return self.fail(true, IsoTpError::Malformed);
        };
        match status {
            CTS => {
                let separation = self
                    .config
                    .st_min_override
                    .unwrap_or_else(|| StMin::from_byte(st_min).duration());
                self.tx = Tx::Consecutive {
                    next_at: now,
                    sequence,
                    block_left: (block_size > 0).then_some(block_size),
                    separation,
                };
            }
            WAIT => {
                let waits = waits.saturating_add(1);
                if waits > self.config.max_wait_frames {
                    return self.fail(true, IsoTpError::WaitFrameOverrun);
                }
                self.tx = Tx::AwaitFlow {
                    deadline: now.saturating_add(self.config.n_bs),
                    waits,
                    sequence,
                };
            }
            OVFLW => self.fail(true, IsoTpError::BufferOverflow),
            other => self.fail(true, IsoTpError::InvalidFlowStatus(other)),
        }
    }

    fn first_frame_payload(&self) -> usize {
        let header = if self.tx_data.len() > 4095 { 6 } else { 2 };
        self.room().saturating_sub(header)
    }

    /// Send what is due at `now`.
    pub fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
        // Flow control first: it keeps the peer's transfer going.
        while let Some(status) = self.flow_due.pop_front() {
            let (bs, st) = (self.config.block_size, self.config.st_min.to_byte());
            if let Some(frame) = self.frame(&[0x30 | status, bs, st]) {
                out(self.port, frame);
            }
        }
        if let Rx::Receiving { deadline, .. } = self.rx {
            if now >= deadline {
                self.fail(false, IsoTpError::TimeoutCr);
            }
        }
        match self.tx.clone() {
            Tx::Idle => {}
            Tx::Start => self.start(now, out),
            Tx::AwaitFlow { deadline, .. } => {
                if now >= deadline {
                    self.fail(true, IsoTpError::TimeoutBs);
                }
            }
            Tx::Consecutive { .. } => self.consecutive(now, out),
        }
    }

    fn start(&mut self, now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
        let len = self.tx_data.len();
        let room = self.room();
        let classic_single = len <= room.saturating_sub(1).min(7);
        let fd_single = self.config.fd && len <= room.saturating_sub(2);
        let mut payload = Vec::with_capacity(64);
        if classic_single {
            payload.push(u8::try_from(len).unwrap_or(0));
        } else if fd_single {
            payload.extend_from_slice(&[0x00, u8::try_from(len).unwrap_or(0)]);
        }
        if classic_single || fd_single {
            payload.extend_from_slice(&self.tx_data);
            if let Some(frame) = self.frame(&payload) {
                out(self.port, frame);
            }
            self.tx = Tx::Idle;
            self.events.push_back(IsoTpEvent::Sent);
            return;
        }
        if len > 4095 {
            let be = u32::try_from(len).unwrap_or(u32::MAX).to_be_bytes();
            payload.extend_from_slice(&[0x10, 0x00]);
            payload.extend_from_slice(&be);
        } else {
            let [hi, lo] = u16::try_from(len).unwrap_or(0).to_be_bytes();
            payload.extend_from_slice(&[0x10 | (hi & 0x0F), lo]);
        }
        let take = self.first_frame_payload().min(len);
        payload.extend_from_slice(self.tx_data.get(..take).unwrap_or(&[]));
        if let Some(frame) = self.frame(&payload) {
            out(self.port, frame);
        }
        self.tx_offset = take;
        self.tx = Tx::AwaitFlow {
            deadline: now.saturating_add(self.config.n_bs),
            waits: 0,
            sequence: 1,
        };
    }

    fn consecutive(&mut self, now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
        // One frame per call when a separation time is due; back to back (bounded by the
        // block) when it is zero.
        for _ in 0..=u8::MAX {
            let Tx::Consecutive {
                next_at,
                sequence,
                block_left,
                separation,
            } = self.tx
            else {
                return;
            };
            if now < next_at {
                return;
            }
            let take = self
                .room()
                .saturating_sub(1)
                .min(self.tx_data.len() - self.tx_offset);
            let mut payload = Vec::with_capacity(64);
            payload.push(0x20 | sequence);
            payload.extend_from_slice(
                self.tx_data
                    .get(self.tx_offset..self.tx_offset + take)
                    .unwrap_or(&[]),
            );
            if let Some(frame) = self.frame(&payload) {
                out(self.port, frame);
            }
            self.tx_offset += take;
            if self.tx_offset >= self.tx_data.len() {
                self.tx = Tx::Idle;
                self.events.push_back(IsoTpEvent::Sent);
                return;
            }
            self.tx = match block_left {
                Some(1) => Tx::AwaitFlow {
                    deadline: now.saturating_add(self.config.n_bs),
                    waits: 0,
                    sequence: (sequence + 1) & 0x0F,
                },
                left => Tx::Consecutive {
                    next_at: now.saturating_add(separation),
                    sequence: (sequence + 1) & 0x0F,
                    block_left: left.map(|n| n - 1),
                    separation,
                },
            };
            if !separation.is_zero() {
                return;
            }
        }
    }

    /// When the channel next has something to do.
    pub fn next_deadline(&self) -> Option<Timestamp> {
        let tx = match self.tx {
            Tx::Idle => None,
            Tx::Start => Some(Timestamp::ZERO),
            Tx::AwaitFlow { deadline, .. } => Some(deadline),
            Tx::Consecutive { next_at, .. } => Some(next_at),
        };
        let rx = match self.rx {
            Rx::Idle => None,
            Rx::Receiving { deadline, .. } => Some(deadline),
        };
        let flow = (!self.flow_due.is_empty()).then_some(Timestamp::ZERO);
        [tx, rx, flow].into_iter().flatten().min()
    }
}

impl bywire_core::node::Node for IsoTp {
    fn on_frame(&mut self, now: Timestamp, port: Port, frame: &Frame) {
        if port == self.port {
            IsoTp::on_frame(self, now, frame);
        }
    }

    fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
        IsoTp::poll(self, now, out);
    }

    fn next_deadline(&self) -> Option<Timestamp> {
        IsoTp::next_deadline(self)
    }
}

/// One frame read as ISO-TP (for dumps): what its PCI says, the data after it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pdu<'a> {
    /// A single frame of `length` bytes.
    Single {
        /// SF_DL.
        length: usize,
        /// The data after the PCI.
        data: &'a [u8],
    },
    /// A first frame announcing `length` bytes.
    First {
        /// FF_DL.
        length: usize,
        /// The data after the PCI.
        data: &'a [u8],
    },
    /// A consecutive frame.
    Consecutive {
        /// Its sequence number.
        sequence: u8,
        /// The data after the PCI.
        data: &'a [u8],
    },
    /// A flow-control frame.
    Flow {
        /// Flow status (0 CTS, 1 WAIT, 2 OVFLW, others invalid).
        status: u8,
        /// Block size.
        block_size: u8,
        /// STmin byte.
        st_min: u8,
    },
    /// A PCI type ISO-TP does not define, or a frame too short for its PCI.
    Unknown,
}

impl Pdu<'_> {
    /// Read `data` (after any addressing byte).
    pub fn parse(data: &[u8]) -> Pdu<'_> {
        let Some(&pci) = data.first() else {
            return Pdu::Unknown;
        };
        let byte = |i: usize| data.get(i).copied();
        let rest = |i: usize| data.get(i..).unwrap_or(&[]);
        match pci >> 4 {
            0 if pci & 0x0F != 0 => Pdu::Single {
                length: usize::from(pci & 0x0F),
                data: rest(1),
            },
            0 => match byte(1) {
                Some(length) => Pdu::Single {
                    length: usize::from(length),
                    data: rest(2),
                },
                None => Pdu::Unknown,
            },
            1 => {
                let Some(low) = byte(1) else {
                    return Pdu::Unknown;
                };
                let short = (usize::from(pci & 0x0F) << 8) | usize::from(low);
                if short != 0 {
                    return Pdu::First {
                        length: short,
                        data: rest(2),
                    };
                }
                match data.get(2..6) {
                    Some(&[a, b, c, d]) => Pdu::First {
                        length: usize::try_from(u32::from_be_bytes([a, b, c, d]))
                            .unwrap_or(usize::MAX),
                        data: rest(6),
                    },
                    _ => Pdu::Unknown,
                }
            }
            2 => Pdu::Consecutive {
                sequence: pci & 0x0F,
                data: rest(1),
            },
            3 => match (byte(1), byte(2)) {
                (Some(block_size), Some(st_min)) => Pdu::Flow {
                    status: pci & 0x0F,
                    block_size,
                    st_min,
                },
                _ => Pdu::Unknown,
            },
            _ => Pdu::Unknown,
        }
    }
}
