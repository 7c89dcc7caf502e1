//! ISO-TP (ISO 15765-2) as a sans-IO node: one channel between two addresses, sending and
//! receiving at once.
//!
//! - Frames: single (classic up to 7 bytes; CAN FD up to 62 with the escape form), first
//!   (12-bit length up to 4095, the 32-bit escape beyond), consecutive, flow control.
//! - Flow control both ways: the receiver's block size and STmin (milliseconds, and the
//!   100–900 µs codes) are honoured when sending and offered when receiving; WAIT frames up to
//!   `max_wait_frames`; OVERFLOW when a message is larger than the receive buffer.
//! - Timers, from the time each call is given: N_Bs (waiting for flow control), N_Cr (waiting
//!   for a consecutive frame) and, when set, N_As/N_Ar (waiting for a frame's own transmit
//!   confirmation, [`Node::on_sent`](bywire_core::node::Node::on_sent)). With confirmations
//!   the channel works as the standard's timing diagram does and as Linux's ISO-TP does: one
//!   frame on its way at a time, N_Bs and N_Cr counted from the confirmation of the frame
//!   before, STmin from the end of the previous consecutive frame, and [`IsoTpEvent::Sent`]
//!   only once the last frame is confirmed. Without (the default, for a caller that drives
//!   the channel by hand) a frame counts as sent when it is handed out.
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

/// The standard's default for its timeouts (N_As, N_Ar, N_Bs, N_Cr).
pub const DEFAULT_TIMEOUT: Duration = Duration::from_millis(1000);

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
    /// Longest wait for the transmit confirmation of a data frame (N_As); `None`: frames are
    /// not confirmed (the runner gives no [`Node::on_sent`](bywire_core::node::Node::on_sent)).
    pub n_as: Option<Duration>,
    /// Longest wait for the transmit confirmation of a flow-control frame (N_Ar).
    pub n_ar: Option<Duration>,
    /// The largest message received (a longer one is refused with OVERFLOW).
    pub max_message: usize,
    /// Separation time used regardless of what the receiver asks (`None`: the receiver's).
    pub st_min_override: Option<Duration>,
    /// Added to the separation before each consecutive frame (Linux's `frame_txtime`,
    /// isotpsend's `-t`).
    pub frame_gap: Duration,
    /// The padding byte received frames must carry (with `rx_padding_check.content`).
    pub rx_padding: Option<u8>,
    /// What is checked of a received frame's padding (isotprecv's `-P`).
    pub rx_padding_check: PaddingCheck,
}

/// Checks of received frames' padding, as Linux's ISO-TP makes them: with an expected
/// padding byte, the frame's length must be a padded one (8, or the CAN FD length covering
/// it) and the bytes after the data that byte; without one, the length must be the shortest.
/// A frame that fails is dropped and the transfer it belongs to fails with
/// [`IsoTpError::Padding`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PaddingCheck {
    /// The frame's length.
    pub length: bool,
    /// The padding bytes' value.
    pub content: bool,
}

impl IsoTpConfig {
    /// Classic frames between `tx_id` and `rx_id`, normal addressing, no padding, BS 0,
    /// STmin 0, N_Bs and N_Cr 1 s, no transmit confirmations, messages up to 4095 bytes.
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
            n_bs: DEFAULT_TIMEOUT,
            n_cr: DEFAULT_TIMEOUT,
            n_as: None,
            n_ar: None,
            max_message: 4095,
            st_min_override: None,
            frame_gap: Duration::ZERO,
            rx_padding: None,
            rx_padding_check: PaddingCheck {
                length: false,
                content: false,
            },
        }
    }

    /// With N_As and N_Ar of `timeout` (the standard's 1000 ms is usual): for a runner that
    /// confirms what it sends, as both of bywire's do.
    pub fn confirmed(mut self, timeout: Duration) -> Self {
        self.n_as = Some(timeout);
        self.n_ar = Some(timeout);
        self
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
#[non_exhaustive]
pub enum IsoTpError {
    /// N_TIMEOUT_A: a frame was not confirmed on the bus in time (N_As sending, N_Ar for a
    /// flow-control frame while receiving).
    TimeoutA,
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
    /// A received frame whose padding is not as [`PaddingCheck`] requires (Linux's EBADMSG).
    Padding,
}

impl fmt::Display for IsoTpError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            IsoTpError::TimeoutA => {
                f.write_str("N_TIMEOUT_A: a frame was not confirmed sent in time (N_As/N_Ar)")
            }
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
            IsoTpError::Padding => f.write_str("a received frame is not padded as required"),
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
#[non_exhaustive]
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

/// A frame handed out and not yet confirmed on the bus.
#[derive(Debug, Clone, PartialEq)]
struct Unconfirmed {
    frame: Frame,
    deadline: Timestamp,
    /// The message's last frame: its confirmation is the message's.
    last: bool,
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
    /// With N_As: the data frame on its way.
    unconfirmed_data: Option<Unconfirmed>,
    /// With N_Ar: the flow-control frame on its way.
    unconfirmed_flow: Option<Unconfirmed>,
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
            unconfirmed_data: None,
            unconfirmed_flow: None,
            events: VecDeque::new(),
        }
    }

    /// The settings.
    pub fn config(&self) -> &IsoTpConfig {
        &self.config
    }

    /// Whether a message is being sent (its last frame not yet confirmed, with N_As).
    pub fn sending(&self) -> bool {
        self.tx != Tx::Idle || self.unconfirmed_data.is_some()
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
            self.unconfirmed_data = None;
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
    fn receive(&mut self, now: Timestamp, frame: &Frame) {
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
        if let Some(used) = self.pdu_length(data, frame.is_fd()) {
            let used = used + self.config.prefix_len();
            if !self.padding_ok(frame.data(), used) {
                // Which transfer the frame belonged to: a flow control is the sender's.
                return self.fail(pci >> 4 == 3, IsoTpError::Padding);
            }
        }
        match pci >> 4 {
            0 => self.on_single(data, frame.is_fd()),
            1 => self.on_first(now, data),
            2 => self.on_consecutive(now, pci & 0x0F, data.get(1..).unwrap_or(&[])),
            3 => self.on_flow(now, data),
            // Reserved PCI types are ignored, as the standard asks.
            _ => {}
        }
    }

    /// The bytes of a received frame (after its addressing byte) that its PDU uses, when it may
    /// be padded: a single frame, flow control, the last consecutive frame of a transfer.
    fn pdu_length(&self, data: &[u8], fd: bool) -> Option<usize> {
        let pci = *data.first()?;
        let used = match pci >> 4 {
            0 if pci & 0x0F == 0 && fd => 2 + usize::from(*data.get(1)?),
            0 => 1 + usize::from(pci & 0x0F),
            2 => match self.rx {
                Rx::Receiving { length, .. } => 1 + length.saturating_sub(self.rx_data.len()),
                Rx::Idle => return None,
            },
            3 => 3,
            _ => return None,
        };
        (used <= data.len()).then_some(used)
    }

    /// Whether a received frame of `used` bytes (addressing byte included) is padded as
    /// required.
    fn padding_ok(&self, frame: &[u8], used: usize) -> bool {
        let check = self.config.rx_padding_check;
        let padded_length = |n: usize| {
            if n <= 8 {
                8
            } else {
                bywire_core::frame::Dlc::fd_covering(n).map_or(64, bywire_core::frame::Dlc::fd_len)
            }
        };
        match self.config.rx_padding {
            // No padding expected: the shortest frame (the CAN FD length covering it).
            None => {
                !check.length
                    || if used <= 8 {
                        frame.len() == used
                    } else {
                        frame.len() == padded_length(used)
                    }
            }
            Some(byte) => {
                (!check.length || frame.len() == padded_length(frame.len()))
                    && (!check.content
                        || frame.get(used..).unwrap_or(&[]).iter().all(|b| *b == byte))
            }
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
                    .unwrap_or_else(|| StMin::from_byte(st_min).duration())
                    .saturating_add(self.config.frame_gap);
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
    fn step(&mut self, now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
        if self
            .unconfirmed_flow
            .as_ref()
            .is_some_and(|u| now >= u.deadline)
        {
            self.unconfirmed_flow = None;
            self.flow_due.clear();
            self.fail(false, IsoTpError::TimeoutA);
        }
        if self
            .unconfirmed_data
            .as_ref()
            .is_some_and(|u| now >= u.deadline)
        {
            self.fail(true, IsoTpError::TimeoutA);
        }
        // Flow control first: it keeps the peer's transfer going (one at a time when each
        // waits for its confirmation).
        while self.unconfirmed_flow.is_none() {
            let Some(status) = self.flow_due.pop_front() else {
                break;
            };
            let (bs, st) = (self.config.block_size, self.config.st_min.to_byte());
            if let Some(frame) = self.frame(&[0x30 | status, bs, st]) {
                if let Some(n_ar) = self.config.n_ar {
                    self.unconfirmed_flow = Some(Unconfirmed {
                        frame,
                        deadline: now.saturating_add(n_ar),
                        last: false,
                    });
                }
                out(self.port, frame);
            }
        }
        if let Rx::Receiving { deadline, .. } = self.rx {
            if now >= deadline {
                self.fail(false, IsoTpError::TimeoutCr);
            }
        }
        if self.unconfirmed_data.is_some() {
            return;
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
            self.tx = Tx::Idle;
            self.emit(now, &payload, true, out);
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
        self.emit(now, &payload, false, out);
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
            self.tx_offset += take;
            let last = self.tx_offset >= self.tx_data.len();
            self.emit(now, &payload, last, out);
            if last {
                self.tx = Tx::Idle;
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
            if !separation.is_zero() || self.unconfirmed_data.is_some() {
                return;
            }
        }
    }

    /// Hand out a data frame with `payload`; with N_As it waits for its confirmation, and the
    /// message's `last` frame is its [`IsoTpEvent::Sent`] once confirmed (at once without).
    fn emit(
        &mut self,
        now: Timestamp,
        payload: &[u8],
        last: bool,
        out: &mut dyn FnMut(Port, Frame),
    ) {
        let Some(frame) = self.frame(payload) else {
            if last {
                self.events.push_back(IsoTpEvent::Sent);
            }
            return;
        };
        match self.config.n_as {
            Some(n_as) => {
                self.unconfirmed_data = Some(Unconfirmed {
                    frame,
                    deadline: now.saturating_add(n_as),
                    last,
                })
            }
            None if last => self.events.push_back(IsoTpEvent::Sent),
            None => {}
        }
        out(self.port, frame);
    }

    /// A frame this channel sent is on the bus: the timers that start at a confirmation start.
    fn confirm(&mut self, now: Timestamp, frame: &Frame) {
        if self
            .unconfirmed_data
            .as_ref()
            .is_some_and(|u| u.frame == *frame)
        {
            if self.unconfirmed_data.take().is_some_and(|u| u.last) {
                self.events.push_back(IsoTpEvent::Sent);
            }
            match &mut self.tx {
                Tx::AwaitFlow { deadline, .. } => {
                    *deadline = now.saturating_add(self.config.n_bs);
                }
                Tx::Consecutive {
                    next_at,
                    separation,
                    ..
                } => *next_at = now.saturating_add(*separation),
                Tx::Idle | Tx::Start => {}
            }
        } else if self
            .unconfirmed_flow
            .as_ref()
            .is_some_and(|u| u.frame == *frame)
        {
            self.unconfirmed_flow = None;
            if let Rx::Receiving { deadline, .. } = &mut self.rx {
                *deadline = now.saturating_add(self.config.n_cr);
            }
        }
    }

    /// When the channel next has something to do.
    fn deadline(&self) -> Option<Timestamp> {
        let tx = match self.tx {
            _ if self.unconfirmed_data.is_some() => {
                self.unconfirmed_data.as_ref().map(|u| u.deadline)
            }
            Tx::Idle => None,
            Tx::Start => Some(Timestamp::ZERO),
            Tx::AwaitFlow { deadline, .. } => Some(deadline),
            Tx::Consecutive { next_at, .. } => Some(next_at),
        };
        let rx = match self.rx {
            Rx::Idle => None,
            Rx::Receiving { deadline, .. } => Some(deadline),
        };
        let flow = match &self.unconfirmed_flow {
            Some(u) => Some(u.deadline),
            None => (!self.flow_due.is_empty()).then_some(Timestamp::ZERO),
        };
        [tx, rx, flow].into_iter().flatten().min()
    }
}

impl bywire_core::node::Node for IsoTp {
    fn on_frame(&mut self, now: Timestamp, port: Port, frame: &Frame) {
        if port == self.port {
            self.receive(now, frame);
        }
    }

    fn on_sent(&mut self, now: Timestamp, port: Port, frame: &Frame) -> bool {
        if port == self.port {
            self.confirm(now, frame);
        }
        port == self.port
    }

    fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
        self.step(now, out);
    }

    fn next_deadline(&self) -> Option<Timestamp> {
        self.deadline()
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
