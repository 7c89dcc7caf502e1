//! CAN frames: identifiers, data length codes, classic, FD, remote and error frames.
//!
//! Frames are plain `Copy` values with no heap storage: a classic frame carries up to 8 bytes,
//! an FD frame up to 64, and every constructor validates, so a [`Frame`] in hand is always one
//! that could exist on a bus. The SocketCAN numeric form (`can_id` with the EFF/RTR/ERR flag
//! bits) is available through [`Frame::socketcan_id`] for filters and OS interfaces.

mod error_frame;
mod text;

pub use error_frame::{ErrorClass, ErrorFrame};
pub use text::{FrameText, ParseFrameError, ParseFrameErrorKind};

/// Extended frame format flag in a SocketCAN `can_id`.
pub const EFF_FLAG: u32 = 0x8000_0000;
/// Remote transmission request flag in a SocketCAN `can_id`.
pub const RTR_FLAG: u32 = 0x4000_0000;
/// Error frame flag in a SocketCAN `can_id`.
pub const ERR_FLAG: u32 = 0x2000_0000;
/// The 11 identifier bits of a standard frame.
pub const SFF_MASK: u32 = 0x0000_07FF;
/// The 29 identifier bits of an extended frame.
pub const EFF_MASK: u32 = 0x1FFF_FFFF;

/// Why a frame could not be built.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum FrameError {
    /// A standard identifier above 0x7FF.
    #[error("standard identifier {0:#X} is above 0x7FF")]
    StandardIdRange(u32),
    /// An extended identifier above 0x1FFFFFFF.
    #[error("extended identifier {0:#X} is above 0x1FFFFFFF")]
    ExtendedIdRange(u32),
    /// More data than the frame kind can carry.
    #[error("{len} data bytes do not fit a {kind} frame (at most {max})")]
    TooLong {
        /// Bytes given.
        len: usize,
        /// Most the frame kind carries.
        max: usize,
        /// "classic" or "CAN FD".
        kind: &'static str,
    },
    /// A length no CAN FD DLC encodes (valid: 0–8, 12, 16, 20, 24, 32, 48, 64).
    #[error("{0} bytes is not a CAN FD length (0-8, 12, 16, 20, 24, 32, 48 or 64)")]
    FdLength(usize),
    /// A DLC above 15.
    #[error("DLC {0} is above 15")]
    DlcRange(u8),
    /// A raw DLC 9–15 given with fewer than 8 data bytes.
    #[error("DLC {dlc} means 8 data bytes, but {len} were given")]
    DlcMismatch {
        /// DLC given.
        dlc: u8,
        /// Bytes given.
        len: usize,
    },
    /// Error class bits outside the 29 that SocketCAN defines.
    #[error("error class {0:#X} has bits outside 0x1FFFFFFF")]
    ErrorClassRange(u32),
}

/// An 11-bit identifier (0..=0x7FF).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct StandardId(u16);

impl StandardId {
    /// The highest standard identifier.
    pub const MAX: StandardId = StandardId(0x7FF);
    /// Identifier 0, the highest priority.
    pub const ZERO: StandardId = StandardId(0);

    /// `Some` when `raw` fits 11 bits.
    pub const fn new(raw: u16) -> Option<Self> {
        if raw <= 0x7FF {
            Some(StandardId(raw))
        } else {
            None
        }
    }

    /// The identifier's value.
    pub const fn as_raw(self) -> u16 {
        self.0
    }
}

/// A 29-bit identifier (0..=0x1FFFFFFF).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ExtendedId(u32);

impl ExtendedId {
    /// The highest extended identifier.
    pub const MAX: ExtendedId = ExtendedId(EFF_MASK);
    /// Identifier 0.
    pub const ZERO: ExtendedId = ExtendedId(0);

    /// `Some` when `raw` fits 29 bits.
    pub const fn new(raw: u32) -> Option<Self> {
        if raw <= EFF_MASK {
            Some(ExtendedId(raw))
        } else {
            None
        }
    }

    /// The identifier's value.
    pub const fn as_raw(self) -> u32 {
        self.0
    }

    /// The 11 most significant bits, sent first (the base identifier).
    pub const fn base(self) -> u16 {
        // 29 - 18 = 11 bits remain after the shift: always fits u16.
        (self.0 >> 18) as u16
    }

    /// The 18 least significant bits (the identifier extension).
    pub const fn extension(self) -> u32 {
        self.0 & 0x3_FFFF
    }
}

/// A standard or extended identifier.
///
/// `Ord` is arbitration priority: the identifier that wins arbitration on the bus sorts first
/// (a standard frame beats an extended frame with the same 11 base bits).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Id {
    /// 11-bit.
    Standard(StandardId),
    /// 29-bit.
    Extended(ExtendedId),
}

impl Id {
    /// A standard identifier, checked.
    pub fn standard(raw: u32) -> Result<Id, FrameError> {
        u16::try_from(raw)
            .ok()
            .and_then(StandardId::new)
            .map(Id::Standard)
            .ok_or(FrameError::StandardIdRange(raw))
    }

    /// An extended identifier, checked.
    pub fn extended(raw: u32) -> Result<Id, FrameError> {
        ExtendedId::new(raw)
            .map(Id::Extended)
            .ok_or(FrameError::ExtendedIdRange(raw))
    }

    /// The identifier's value without format.
    pub const fn as_raw(self) -> u32 {
        match self {
            Id::Standard(id) => id.0 as u32,
            Id::Extended(id) => id.0,
        }
    }

    /// Whether this is a 29-bit identifier.
    pub const fn is_extended(self) -> bool {
        matches!(self, Id::Extended(_))
    }

    /// Sort key in bus arbitration order: the base identifier, then SRR/RTR position (standard
    /// frames send a dominant RTR where extended frames send a recessive SRR), then the extension;
    /// packed into one word (11 + 1 + 18 bits), as the bits go out on the wire. A simulated bus
    /// compares identifiers many times a frame.
    pub const fn arbitration_key(self) -> u32 {
        match self {
            Id::Standard(id) => (id.0 as u32) << 19,
            Id::Extended(id) => (id.base() as u32) << 19 | 1 << 18 | id.extension(),
        }
    }
}

impl PartialOrd for Id {
    fn partial_cmp(&self, other: &Self) -> Option<core::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Id {
    fn cmp(&self, other: &Self) -> core::cmp::Ordering {
        self.arbitration_key().cmp(&other.arbitration_key())
    }
}

impl From<StandardId> for Id {
    fn from(id: StandardId) -> Self {
        Id::Standard(id)
    }
}

impl From<ExtendedId> for Id {
    fn from(id: ExtendedId) -> Self {
        Id::Extended(id)
    }
}

/// A 4-bit data length code.
///
/// Classic CAN: DLC 0–8 is the byte count and 9–15 also mean 8 bytes (the raw value is kept,
/// as SocketCAN's `len8_dlc` does). CAN FD: 9–15 mean 12, 16, 20, 24, 32, 48, 64 bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Dlc(u8);

/// Byte count for each FD DLC.
const FD_LENGTHS: [u8; 16] = [0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64];

impl Dlc {
    /// `Some` for 0..=15.
    pub const fn new(raw: u8) -> Option<Dlc> {
        if raw <= 15 {
            Some(Dlc(raw))
        } else {
            None
        }
    }

    /// The DLC in the low 4 bits of `raw` (the rest ignored), as read from a 4-bit field.
    pub const fn from_nibble(raw: u8) -> Dlc {
        Dlc(raw & 0x0F)
    }

    /// The code's value, 0..=15.
    pub const fn as_raw(self) -> u8 {
        self.0
    }

    /// Bytes carried by a classic frame with this DLC.
    pub const fn classic_len(self) -> usize {
        if self.0 > 8 {
            8
        } else {
            self.0 as usize
        }
    }

    /// Bytes carried by an FD frame with this DLC.
    pub fn fd_len(self) -> usize {
        FD_LENGTHS
            .get(usize::from(self.0))
            .map_or(64, |&len| usize::from(len))
    }

    /// The DLC of a classic frame of `len` bytes (0..=8).
    pub fn from_classic_len(len: usize) -> Option<Dlc> {
        u8::try_from(len).ok().filter(|&l| l <= 8).map(Dlc)
    }

    /// The DLC whose FD length is exactly `len`.
    pub fn from_fd_len(len: usize) -> Option<Dlc> {
        FD_LENGTHS
            .iter()
            .position(|&l| usize::from(l) == len)
            .and_then(|p| u8::try_from(p).ok())
            .map(Dlc)
    }

    /// The smallest DLC whose FD length holds `len` bytes (the padding a controller applies).
    pub fn fd_covering(len: usize) -> Option<Dlc> {
        FD_LENGTHS
            .iter()
            .position(|&l| usize::from(l) >= len)
            .and_then(|p| u8::try_from(p).ok())
            .map(Dlc)
    }
}

/// A classic CAN data or remote frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ClassicFrame {
    id: Id,
    remote: bool,
    dlc: Dlc,
    data: [u8; 8],
}

impl ClassicFrame {
    /// A data frame with 0–8 bytes; the DLC is the length.
    pub fn new(id: Id, data: &[u8]) -> Result<Self, FrameError> {
        let dlc = Dlc::from_classic_len(data.len()).ok_or(FrameError::TooLong {
            len: data.len(),
            max: 8,
            kind: "classic",
        })?;
        Self::with_dlc(id, dlc, data)
    }

    /// A data frame with an explicit DLC; DLC 9–15 need exactly 8 bytes.
    pub fn with_dlc(id: Id, dlc: Dlc, data: &[u8]) -> Result<Self, FrameError> {
        if data.len() != dlc.classic_len() {
            return Err(if data.len() > 8 {
                FrameError::TooLong {
                    len: data.len(),
                    max: 8,
                    kind: "classic",
                }
            } else {
                FrameError::DlcMismatch {
                    dlc: dlc.0,
                    len: data.len(),
                }
            });
        }
        let mut bytes = [0u8; 8];
        for (dst, src) in bytes.iter_mut().zip(data) {
            *dst = *src;
        }
        Ok(ClassicFrame {
            id,
            remote: false,
            dlc,
            data: bytes,
        })
    }

    /// A remote frame requesting `dlc` (the DLC field is sent, no data).
    pub fn remote(id: Id, dlc: Dlc) -> Self {
        ClassicFrame {
            id,
            remote: true,
            dlc,
            data: [0; 8],
        }
    }

    /// The identifier.
    pub fn id(&self) -> Id {
        self.id
    }

    /// Whether this is a remote frame.
    pub fn is_remote(&self) -> bool {
        self.remote
    }

    /// The DLC as sent on the wire.
    pub fn dlc(&self) -> Dlc {
        self.dlc
    }

    /// The data bytes (empty for a remote frame).
    pub fn data(&self) -> &[u8] {
        let len = if self.remote {
            0
        } else {
            self.dlc.classic_len()
        };
        self.data.get(..len).unwrap_or(&[])
    }

    /// Byte count: the data length, or for a remote frame the requested length.
    pub fn len(&self) -> usize {
        self.dlc.classic_len()
    }

    /// Whether the frame has no data bytes.
    pub fn is_empty(&self) -> bool {
        self.data().is_empty()
    }
}

/// A CAN FD frame (ISO 11898-1:2015 format).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct FdFrame {
    id: Id,
    brs: bool,
    esi: bool,
    len: u8,
    data: [u8; 64],
}

impl FdFrame {
    /// An FD frame; `data.len()` must be a valid FD length (see [`FdFrame::padded`]).
    pub fn new(id: Id, data: &[u8], brs: bool, esi: bool) -> Result<Self, FrameError> {
        if data.len() > 64 {
            return Err(FrameError::TooLong {
                len: data.len(),
                max: 64,
                kind: "CAN FD",
            });
        }
        if Dlc::from_fd_len(data.len()).is_none() {
            return Err(FrameError::FdLength(data.len()));
        }
        let mut bytes = [0u8; 64];
        for (dst, src) in bytes.iter_mut().zip(data) {
            *dst = *src;
        }
        Ok(FdFrame {
            id,
            brs,
            esi,
            len: u8::try_from(data.len()).map_err(|_| FrameError::FdLength(data.len()))?,
            data: bytes,
        })
    }

    /// An FD frame whose data is padded with zeros up to the next valid FD length.
    pub fn padded(id: Id, data: &[u8], brs: bool, esi: bool) -> Result<Self, FrameError> {
        let dlc = Dlc::fd_covering(data.len()).ok_or(FrameError::TooLong {
            len: data.len(),
            max: 64,
            kind: "CAN FD",
        })?;
        let mut bytes = [0u8; 64];
        for (dst, src) in bytes.iter_mut().zip(data) {
            *dst = *src;
        }
        Self::new(id, bytes.get(..dlc.fd_len()).unwrap_or(&[]), brs, esi)
    }

    /// The identifier.
    pub fn id(&self) -> Id {
        self.id
    }

    /// Bit rate switch: the data phase runs at the data bitrate.
    pub fn brs(&self) -> bool {
        self.brs
    }

    /// Error state indicator: the sender is error passive.
    pub fn esi(&self) -> bool {
        self.esi
    }

    /// The DLC sent on the wire.
    pub fn dlc(&self) -> Dlc {
        Dlc::from_fd_len(usize::from(self.len)).unwrap_or(Dlc(15))
    }

    /// The data bytes.
    pub fn data(&self) -> &[u8] {
        self.data.get(..usize::from(self.len)).unwrap_or(&[])
    }

    /// Number of data bytes.
    pub fn len(&self) -> usize {
        usize::from(self.len)
    }

    /// Whether the frame has no data bytes.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
}

/// Any frame a CAN interface can deliver.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Frame {
    /// Classic data or remote frame.
    Classic(ClassicFrame),
    /// CAN FD frame.
    Fd(FdFrame),
    /// An error report from the controller (SocketCAN error frame), not a frame on the wire.
    Error(ErrorFrame),
}

impl Frame {
    /// A classic data frame.
    pub fn classic(id: Id, data: &[u8]) -> Result<Frame, FrameError> {
        ClassicFrame::new(id, data).map(Frame::Classic)
    }

    /// A classic remote frame.
    pub fn remote(id: Id, dlc: Dlc) -> Frame {
        Frame::Classic(ClassicFrame::remote(id, dlc))
    }

    /// An FD frame with an exact FD length.
    pub fn fd(id: Id, data: &[u8], brs: bool, esi: bool) -> Result<Frame, FrameError> {
        FdFrame::new(id, data, brs, esi).map(Frame::Fd)
    }

    /// The identifier; `None` for error frames.
    pub fn id(&self) -> Option<Id> {
        match self {
            Frame::Classic(f) => Some(f.id),
            Frame::Fd(f) => Some(f.id),
            Frame::Error(_) => None,
        }
    }

    /// The data bytes (for an error frame, its 8 detail bytes).
    pub fn data(&self) -> &[u8] {
        match self {
            Frame::Classic(f) => f.data(),
            Frame::Fd(f) => f.data(),
            Frame::Error(f) => f.data(),
        }
    }

    /// Whether this is a remote frame.
    pub fn is_remote(&self) -> bool {
        matches!(self, Frame::Classic(f) if f.remote)
    }

    /// Whether this is an FD frame.
    pub fn is_fd(&self) -> bool {
        matches!(self, Frame::Fd(_))
    }

    /// Whether this is an error frame.
    pub fn is_error(&self) -> bool {
        matches!(self, Frame::Error(_))
    }

    /// The DLC sent on the wire (error frames: the DLC of their 8 detail bytes).
    pub fn dlc(&self) -> Dlc {
        match self {
            Frame::Classic(f) => f.dlc,
            Frame::Fd(f) => f.dlc(),
            Frame::Error(_) => Dlc(8),
        }
    }

    /// The SocketCAN `can_id`: identifier plus EFF, RTR and ERR flag bits.
    pub fn socketcan_id(&self) -> u32 {
        let with_format = |id: Id| match id {
            Id::Standard(s) => u32::from(s.0),
            Id::Extended(e) => e.0 | EFF_FLAG,
        };
        match self {
            Frame::Classic(f) => with_format(f.id) | if f.remote { RTR_FLAG } else { 0 },
            Frame::Fd(f) => with_format(f.id),
            Frame::Error(f) => ERR_FLAG | f.class_bits(),
        }
    }
}

impl From<ClassicFrame> for Frame {
    fn from(f: ClassicFrame) -> Self {
        Frame::Classic(f)
    }
}

impl From<FdFrame> for Frame {
    fn from(f: FdFrame) -> Self {
        Frame::Fd(f)
    }
}

impl From<ErrorFrame> for Frame {
    fn from(f: ErrorFrame) -> Self {
        Frame::Error(f)
    }
}

impl From<Id> for embedded_can::Id {
    fn from(id: Id) -> Self {
        match id {
            // Both constructors accept every value our types can hold; the fallbacks are never taken.
            Id::Standard(s) => embedded_can::StandardId::new(s.0).map_or(
                embedded_can::Id::Standard(embedded_can::StandardId::ZERO),
                embedded_can::Id::Standard,
            ),
            Id::Extended(e) => embedded_can::ExtendedId::new(e.0).map_or(
                embedded_can::Id::Extended(embedded_can::ExtendedId::ZERO),
                embedded_can::Id::Extended,
            ),
        }
    }
}

impl From<embedded_can::Id> for Id {
    fn from(id: embedded_can::Id) -> Self {
        match id {
            embedded_can::Id::Standard(s) => Id::Standard(StandardId(s.as_raw())),
            embedded_can::Id::Extended(e) => Id::Extended(ExtendedId(e.as_raw())),
        }
    }
}

/// Interop with the `embedded-can` ecosystem (socketcan-rs, embassy, HAL drivers): classic frames.
impl embedded_can::Frame for ClassicFrame {
    fn new(id: impl Into<embedded_can::Id>, data: &[u8]) -> Option<Self> {
        ClassicFrame::new(Id::from(id.into()), data).ok()
    }

    fn new_remote(id: impl Into<embedded_can::Id>, dlc: usize) -> Option<Self> {
        let dlc = Dlc::from_classic_len(dlc)?;
        Some(ClassicFrame::remote(Id::from(id.into()), dlc))
    }

    fn is_extended(&self) -> bool {
        self.id.is_extended()
    }

    fn is_remote_frame(&self) -> bool {
        self.remote
    }

    fn id(&self) -> embedded_can::Id {
        self.id.into()
    }

    fn dlc(&self) -> usize {
        self.dlc.classic_len()
    }

    fn data(&self) -> &[u8] {
        ClassicFrame::data(self)
    }
}

/// Interop with `embedded-can`: `new` builds a classic frame for up to 8 bytes and an FD frame
/// (without bit rate switch) for valid FD lengths above 8; error frames report identifier 0.
impl embedded_can::Frame for Frame {
    fn new(id: impl Into<embedded_can::Id>, data: &[u8]) -> Option<Self> {
        let id = Id::from(id.into());
        if data.len() <= 8 {
            Frame::classic(id, data).ok()
        } else {
            Frame::fd(id, data, false, false).ok()
        }
    }

    fn new_remote(id: impl Into<embedded_can::Id>, dlc: usize) -> Option<Self> {
        <ClassicFrame as embedded_can::Frame>::new_remote(id, dlc).map(Frame::Classic)
    }

    fn is_extended(&self) -> bool {
        self.id().is_some_and(Id::is_extended)
    }

    fn is_remote_frame(&self) -> bool {
        Frame::is_remote(self)
    }

    fn id(&self) -> embedded_can::Id {
        Frame::id(self)
            .unwrap_or(Id::Standard(StandardId::ZERO))
            .into()
    }

    fn dlc(&self) -> usize {
        match self {
            Frame::Classic(f) => f.dlc.classic_len(),
            Frame::Fd(f) => f.len(),
            Frame::Error(f) => f.data().len(),
        }
    }

    fn data(&self) -> &[u8] {
        Frame::data(self)
    }
}
