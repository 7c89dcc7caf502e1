//! SocketCAN error frames: what the controller reports about the bus (`linux/can/error.h`).

use core::fmt;

use super::{FrameError, EFF_MASK};

/// One SocketCAN error class (a bit of the error frame's `can_id`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u32)]
pub enum ErrorClass {
    /// TX timeout (by netdevice driver).
    TxTimeout = 0x0001,
    /// Lost arbitration; data\[0\] holds the bit position.
    LostArbitration = 0x0002,
    /// Controller problems; data\[1\] holds the details.
    Controller = 0x0004,
    /// Protocol violations; data\[2\] the type, data\[3\] the location.
    Protocol = 0x0008,
    /// Transceiver status; data\[4\].
    Transceiver = 0x0010,
    /// No acknowledgement on transmission.
    NoAck = 0x0020,
    /// Bus off.
    BusOff = 0x0040,
    /// Bus error (may flood).
    BusError = 0x0080,
    /// Controller restarted after bus-off.
    Restarted = 0x0100,
    /// TX/RX error counters in data\[6\] and data\[7\].
    Counters = 0x0200,
}

impl ErrorClass {
    /// Every class, in bit order.
    pub const ALL: [ErrorClass; 10] = [
        ErrorClass::TxTimeout,
        ErrorClass::LostArbitration,
        ErrorClass::Controller,
        ErrorClass::Protocol,
        ErrorClass::Transceiver,
        ErrorClass::NoAck,
        ErrorClass::BusOff,
        ErrorClass::BusError,
        ErrorClass::Restarted,
        ErrorClass::Counters,
    ];

    /// The class's bit in the `can_id`.
    pub const fn bit(self) -> u32 {
        self as u32
    }

    /// The words can-utils prints for this class.
    pub const fn name(self) -> &'static str {
        match self {
            ErrorClass::TxTimeout => "tx-timeout",
            ErrorClass::LostArbitration => "lost-arbitration",
            ErrorClass::Controller => "controller-problem",
            ErrorClass::Protocol => "protocol-violation",
            ErrorClass::Transceiver => "transceiver-status",
            ErrorClass::NoAck => "no-acknowledgement-on-tx",
            ErrorClass::BusOff => "bus-off",
            ErrorClass::BusError => "bus-error",
            ErrorClass::Restarted => "restarted-after-bus-off",
            ErrorClass::Counters => "error-counter-tx-rx",
        }
    }
}

/// An error frame: error class bits and the 8 detail bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ErrorFrame {
    class: u32,
    data: [u8; 8],
}

/// Controller problem bits in data\[1\].
const CONTROLLER_PROBLEMS: [(u8, &str); 7] = [
    (0x01, "rx-overflow"),
    (0x02, "tx-overflow"),
    (0x04, "rx-error-warning"),
    (0x08, "tx-error-warning"),
    (0x10, "rx-error-passive"),
    (0x20, "tx-error-passive"),
    (0x40, "back-to-error-active"),
];

/// Protocol violation type bits in data\[2\].
const PROTOCOL_TYPES: [(u8, &str); 8] = [
    (0x01, "single-bit-error"),
    (0x02, "frame-format-error"),
    (0x04, "bit-stuffing-error"),
    (0x08, "tx-dominant-bit-error"),
    (0x10, "tx-recessive-bit-error"),
    (0x20, "bus-overload"),
    (0x40, "back-to-error-active"),
    (0x80, "error-on-tx"),
];

/// Protocol violation location codes in data\[3\].
fn protocol_location(code: u8) -> Option<&'static str> {
    Some(match code {
        0x02 => "id.28-to-id.21",
        0x03 => "start-of-frame",
        0x04 => "bit-srtr",
        0x05 => "bit-ide",
        0x06 => "id.20-to-id.18",
        0x07 => "id.17-to-id.13",
        0x08 => "crc-sequence",
        0x09 => "reserved-bit-0",
        0x0A => "data-field",
        0x0B => "data-length-code",
        0x0C => "bit-rtr",
        0x0D => "reserved-bit-1",
        0x0E => "id.4-to-id.0",
        0x0F => "id.12-to-id.5",
        0x11 => "active-error-flag",
        0x12 => "intermission",
        0x13 => "tolerate-dominant-bits",
        0x16 => "passive-error-flag",
        0x17 => "error-delimiter",
        0x18 => "crc-delimiter",
        0x19 => "acknowledge-slot",
        0x1A => "end-of-frame",
        0x1B => "acknowledge-delimiter",
        0x1C => "overload-flag",
        _ => return None,
    })
}

impl ErrorFrame {
    /// An error frame from the class bits (without the ERR flag) and up to 8 detail bytes.
    pub fn new(class: u32, data: &[u8]) -> Result<Self, FrameError> {
        if class & !EFF_MASK != 0 {
            return Err(FrameError::ErrorClassRange(class));
        }
        if data.len() > 8 {
            return Err(FrameError::TooLong {
                len: data.len(),
                max: 8,
                kind: "error",
            });
        }
        let mut bytes = [0u8; 8];
        for (dst, src) in bytes.iter_mut().zip(data) {
            *dst = *src;
        }
        Ok(ErrorFrame { class, data: bytes })
    }

    /// An error frame from class bits and all 8 detail bytes; class bits outside the 29 the
    /// `can_id` has room for are dropped.
    pub const fn from_array(class: u32, data: [u8; 8]) -> Self {
        ErrorFrame {
            class: class & EFF_MASK,
            data,
        }
    }

    /// The class bits (the `can_id` without the ERR flag).
    pub fn class_bits(&self) -> u32 {
        self.class
    }

    /// Whether the frame reports `class`.
    pub fn has(&self, class: ErrorClass) -> bool {
        self.class & class.bit() != 0
    }

    /// The 8 detail bytes.
    pub fn data(&self) -> &[u8] {
        &self.data
    }

    /// The transmit and receive error counters, when the frame carries them.
    pub fn counters(&self) -> Option<(u8, u8)> {
        let (tec, rec) = (self.data[6], self.data[7]);
        (self.has(ErrorClass::Counters) || tec != 0 || rec != 0).then_some((tec, rec))
    }

    /// The error in words, as can-utils prints it (`bus-error,protocol-violation{{...}{...}}`).
    pub fn describe(&self) -> impl fmt::Display + '_ {
        Describe(self, ",")
    }

    /// The same with another separator between the items (`candump -e` puts each on its own
    /// line with `"\n\t"`).
    pub fn describe_with<'a>(&'a self, separator: &'a str) -> impl fmt::Display + 'a {
        Describe(self, separator)
    }
}

struct Describe<'a>(&'a ErrorFrame, &'a str);

fn write_bits(f: &mut fmt::Formatter<'_>, value: u8, names: &[(u8, &str)]) -> fmt::Result {
    let mut first = true;
    for (bit, name) in names {
        if value & bit != 0 {
            if !first {
                f.write_str(",")?;
            }
            f.write_str(name)?;
            first = false;
        }
    }
    Ok(())
}

impl fmt::Display for Describe<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (frame, separator) = (self.0, self.1);
        let mut first = true;
        for class in ErrorClass::ALL {
            if !frame.has(class) || class == ErrorClass::Counters {
                continue;
            }
            if !first {
                f.write_str(separator)?;
            }
            first = false;
            f.write_str(class.name())?;
            match class {
                ErrorClass::LostArbitration => write!(f, "{{at bit {}}}", frame.data[0])?,
                ErrorClass::Controller => {
                    f.write_str("{")?;
                    write_bits(f, frame.data[1], &CONTROLLER_PROBLEMS)?;
                    f.write_str("}")?;
                }
                ErrorClass::Protocol => {
                    f.write_str("{{")?;
                    write_bits(f, frame.data[2], &PROTOCOL_TYPES)?;
                    f.write_str("}{")?;
                    if let Some(location) = protocol_location(frame.data[3]) {
                        f.write_str(location)?;
                    }
                    f.write_str("}}")?;
                }
                _ => {}
            }
        }
        if let Some((tec, rec)) = frame.counters() {
            if !first {
                f.write_str(separator)?;
            }
            write!(f, "error-counter-tx-rx{{{{{tec}}}{{{rec}}}}}")?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::string::ToString;

    #[test]
    fn describes_classes_and_details_in_can_utils_words() {
        let f = ErrorFrame::new(0x0088, &[0, 0, 0x04, 0x0A, 0, 0, 0, 0]).unwrap();
        assert_eq!(
            f.describe().to_string(),
            "protocol-violation{{bit-stuffing-error}{data-field}},bus-error"
        );
        let f = ErrorFrame::new(0x0204, &[0, 0x20, 0, 0, 0, 0, 136, 0]).unwrap();
        assert_eq!(
            f.describe().to_string(),
            "controller-problem{tx-error-passive},error-counter-tx-rx{{136}{0}}"
        );
        assert!(ErrorFrame::new(0x2000_0000, &[]).is_err());
    }
}
