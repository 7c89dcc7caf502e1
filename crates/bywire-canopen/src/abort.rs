//! SDO abort codes (CiA 301, 7.2.4.3.17): why a transfer or an object access was refused.

use core::fmt;

/// An SDO abort code. Codes this crate does not know are kept as [`Abort::Other`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Abort {
    /// 0503 0000: toggle bit not alternated.
    ToggleNotAlternated,
    /// 0504 0000: SDO protocol timed out.
    Timeout,
    /// 0504 0001: client/server command specifier not valid or unknown.
    InvalidCommand,
    /// 0504 0002: invalid block size (block mode only).
    InvalidBlockSize,
    /// 0504 0003: invalid sequence number (block mode only).
    InvalidSequence,
    /// 0504 0004: CRC error (block mode only).
    CrcError,
    /// 0504 0005: out of memory.
    OutOfMemory,
    /// 0601 0000: unsupported access to an object.
    UnsupportedAccess,
    /// 0601 0001: attempt to read a write-only object.
    ReadWriteOnly,
    /// 0601 0002: attempt to write a read-only object.
    WriteReadOnly,
    /// 0602 0000: object does not exist in the object dictionary.
    NoObject,
    /// 0604 0041: object cannot be mapped to the PDO.
    NotMappable,
    /// 0604 0042: the number and length of the objects to be mapped would exceed the PDO length.
    PdoTooLong,
    /// 0604 0043: general parameter incompatibility.
    Incompatible,
    /// 0604 0047: general internal incompatibility in the device.
    InternalIncompatibility,
    /// 0606 0000: access failed due to a hardware error.
    Hardware,
    /// 0607 0010: data type does not match, length of service parameter does not match.
    LengthMismatch,
    /// 0607 0012: data type does not match, length of service parameter too high.
    LengthTooHigh,
    /// 0607 0013: data type does not match, length of service parameter too low.
    LengthTooLow,
    /// 0609 0011: sub-index does not exist.
    NoSubindex,
    /// 0609 0030: invalid value for parameter (download only).
    InvalidValue,
    /// 0609 0031: value of parameter written too high (download only).
    ValueTooHigh,
    /// 0609 0032: value of parameter written too low (download only).
    ValueTooLow,
    /// 060A 0023: resource not available: SDO connection.
    NoResource,
    /// 0800 0000: general error.
    General,
    /// 0800 0020: data cannot be transferred or stored to the application.
    CannotStore,
    /// 0800 0021: ... because of local control.
    LocalControl,
    /// 0800 0022: ... because of the present device state.
    DeviceState,
    /// 0800 0024: no data available.
    NoData,
    /// A code not in this list, as received.
    Other(u32),
}

const TABLE: [(Abort, u32, &str); 29] = [
    (
        Abort::ToggleNotAlternated,
        0x0503_0000,
        "toggle bit not alternated",
    ),
    (Abort::Timeout, 0x0504_0000, "SDO protocol timed out"),
    (
        Abort::InvalidCommand,
        0x0504_0001,
        "command specifier not valid or unknown",
    ),
    (Abort::InvalidBlockSize, 0x0504_0002, "invalid block size"),
    (
        Abort::InvalidSequence,
        0x0504_0003,
        "invalid sequence number",
    ),
    (Abort::CrcError, 0x0504_0004, "CRC error"),
    (Abort::OutOfMemory, 0x0504_0005, "out of memory"),
    (
        Abort::UnsupportedAccess,
        0x0601_0000,
        "unsupported access to an object",
    ),
    (
        Abort::ReadWriteOnly,
        0x0601_0001,
        "attempt to read a write-only object",
    ),
    (
        Abort::WriteReadOnly,
        0x0601_0002,
        "attempt to write a read-only object",
    ),
    (
        Abort::NoObject,
        0x0602_0000,
        "object does not exist in the object dictionary",
    ),
    (
        Abort::NotMappable,
        0x0604_0041,
        "object cannot be mapped to the PDO",
    ),
    (
        Abort::PdoTooLong,
        0x0604_0042,
        "mapped objects would exceed the PDO length",
    ),
    (
        Abort::Incompatible,
        0x0604_0043,
        "general parameter incompatibility",
    ),
    (
        Abort::InternalIncompatibility,
        0x0604_0047,
        "general internal incompatibility in the device",
    ),
    (
        Abort::Hardware,
        0x0606_0000,
        "access failed due to a hardware error",
    ),
    (
        Abort::LengthMismatch,
        0x0607_0010,
        "length of service parameter does not match",
    ),
    (
        Abort::LengthTooHigh,
        0x0607_0012,
        "length of service parameter too high",
    ),
    (
        Abort::LengthTooLow,
        0x0607_0013,
        "length of service parameter too low",
    ),
    (Abort::NoSubindex, 0x0609_0011, "sub-index does not exist"),
    (
        Abort::InvalidValue,
        0x0609_0030,
        "invalid value for parameter",
    ),
    (
        Abort::ValueTooHigh,
        0x0609_0031,
        "value of parameter written too high",
    ),
    (
        Abort::ValueTooLow,
        0x0609_0032,
        "value of parameter written too low",
    ),
    (
        Abort::NoResource,
        0x060A_0023,
        "resource not available: SDO connection",
    ),
    (Abort::General, 0x0800_0000, "general error"),
    (
        Abort::CannotStore,
        0x0800_0020,
        "data cannot be transferred or stored to the application",
    ),
    (
        Abort::LocalControl,
        0x0800_0021,
        "data cannot be stored because of local control",
    ),
    (
        Abort::DeviceState,
        0x0800_0022,
        "data cannot be stored in the present device state",
    ),
    (Abort::NoData, 0x0800_0024, "no data available"),
];

impl Abort {
    /// The 32-bit code on the wire.
    pub fn code(self) -> u32 {
        match self {
            Abort::Other(code) => code,
            known => TABLE
                .iter()
                .find(|(abort, _, _)| *abort == known)
                .map_or(0x0800_0000, |(_, code, _)| *code),
        }
    }

    /// The abort a code names.
    pub fn from_code(code: u32) -> Abort {
        TABLE
            .iter()
            .find(|(_, known, _)| *known == code)
            .map_or(Abort::Other(code), |(abort, _, _)| *abort)
    }

    /// CiA 301's description.
    pub fn description(self) -> &'static str {
        TABLE
            .iter()
            .find(|(abort, _, _)| *abort == self)
            .map_or("unknown abort code", |(_, _, text)| text)
    }
}

impl fmt::Display for Abort {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "0x{:08X} ({})", self.code(), self.description())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_round_trip_and_unknown_codes_are_kept() {
        for (abort, code, _) in TABLE {
            assert_eq!(abort.code(), code);
            assert_eq!(Abort::from_code(code), abort);
        }
        assert_eq!(Abort::from_code(0x1234_5678), Abort::Other(0x1234_5678));
        assert_eq!(Abort::Other(0x1234_5678).code(), 0x1234_5678);
        assert_eq!(
            Abort::WriteReadOnly.to_string(),
            "0x06010002 (attempt to write a read-only object)"
        );
    }
}
