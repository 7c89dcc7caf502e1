//! Emergency messages (EMCY, CiA 301): their codes, the error register's bits, and reading
//! one off the bus. No allocation: a master's drive controller stops on them.

use bywire_core::frame::Frame;

use crate::nmt::cob_id;

/// EMCY codes this crate raises itself (CiA 301 table 21).
pub mod emcy_code {
    /// Generic error.
    pub const GENERIC: u16 = 0x1000;
    /// Heartbeat or life guard error.
    pub const HEARTBEAT: u16 = 0x8130;
    /// PDO not processed due to length error.
    pub const PDO_LENGTH: u16 = 0x8210;
    /// RPDO timeout.
    pub const RPDO_TIMEOUT: u16 = 0x8250;
    /// Error reset / no error.
    pub const NO_ERROR: u16 = 0x0000;
}

/// An emergency message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Emergency {
    /// The emergency error code (0 = error reset).
    pub code: u16,
    /// The error register (0x1001) at the time.
    pub register: u8,
    /// Manufacturer-specific bytes.
    pub data: [u8; 5],
}

impl Emergency {
    /// Read an EMCY frame from the default COB-IDs (0x81..=0xFF): `(node, emergency)`.
    pub fn parse(frame: &Frame) -> Option<(u8, Emergency)> {
        let id = cob_id(frame)?;
        if !(0x81..=0xFF).contains(&id) || frame.is_remote() {
            return None;
        }
        let &[lo, hi, register, a, b, c, d, e] = frame.data() else {
            return None;
        };
        Some((
            u8::try_from(id - 0x80).ok()?,
            Emergency {
                code: u16::from_le_bytes([lo, hi]),
                register,
                data: [a, b, c, d, e],
            },
        ))
    }

    #[cfg(feature = "alloc")]
    pub(crate) fn payload(&self) -> [u8; 8] {
        let [lo, hi] = self.code.to_le_bytes();
        let [a, b, c, d, e] = self.data;
        [lo, hi, self.register, a, b, c, d, e]
    }
}

/// EMCY error code (CiA 301): the controller recovered from bus-off.
pub const RECOVERED_FROM_BUS_OFF: u16 = 0x8140;

/// Error register (0x1001) bits.
pub mod error_register {
    /// Generic error (set whenever any other is).
    pub const GENERIC: u8 = 0x01;
    /// Current.
    pub const CURRENT: u8 = 0x02;
    /// Voltage.
    pub const VOLTAGE: u8 = 0x04;
    /// Temperature.
    pub const TEMPERATURE: u8 = 0x08;
    /// Communication error (overrun, error state, heartbeat).
    pub const COMMUNICATION: u8 = 0x10;
    /// Device profile specific.
    pub const PROFILE: u8 = 0x20;
    /// Manufacturer specific.
    pub const MANUFACTURER: u8 = 0x80;
}
