//! What a tester knows of an ECU beyond the bytes: its DIDs' names, lengths and value types,
//! and its DTCs' names — to split a multi-DID answer, read snapshots, and print values as
//! people read them. DTCs print in the SAE J2012 form (`U0073-00`).

use alloc::collections::BTreeMap;
use alloc::format;
use alloc::string::{String, ToString};
use alloc::vec::Vec;

use crate::uds::status;

/// How a DID's bytes read.
#[derive(Debug, Clone, PartialEq)]
pub enum ValueKind {
    /// Text (trailing NULs and spaces dropped).
    Ascii,
    /// Bytes, shown in hex.
    Bytes,
    /// A big-endian number of the DID's length (1 to 8 bytes), `raw × scale + offset`.
    Number {
        /// Two's complement.
        signed: bool,
        /// The factor.
        scale: f64,
        /// The offset.
        offset: f64,
        /// The unit ("" for none).
        unit: String,
    },
    /// Several big-endian numbers of `width` bytes each, each `raw × scale`.
    Array {
        /// Bytes per element (1, 2 or 4).
        width: usize,
        /// Two's complement.
        signed: bool,
        /// The factor.
        scale: f64,
        /// The unit.
        unit: String,
    },
}

/// A DID as the tester knows it.
#[derive(Debug, Clone, PartialEq)]
pub struct DidInfo {
    /// Its name.
    pub name: String,
    /// Its length in bytes (`None`: any, only as a request's last DID).
    pub length: Option<usize>,
    /// How its bytes read.
    pub kind: ValueKind,
}

/// What a tester knows of one ECU.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Description {
    /// DIDs by identifier.
    pub dids: BTreeMap<u16, DidInfo>,
    /// DTC names by DTC (24 bits).
    pub dtcs: BTreeMap<u32, String>,
}

impl Description {
    /// The identifiers ISO 14229-1 (annex C) defines as text: part numbers, serial number,
    /// VIN (17 characters), versions, names.
    pub fn iso14229() -> Self {
        let mut d = Description::default();
        let names: [(u16, &str); 14] = [
            (0xF187, "spare part number"),
            (0xF188, "ECU software number"),
            (0xF189, "ECU software version number"),
            (0xF18A, "system supplier identifier"),
            (0xF18B, "ECU manufacturing date"),
            (0xF18C, "ECU serial number"),
            (0xF190, "VIN"),
            (0xF191, "ECU hardware number"),
            (0xF192, "supplier ECU hardware number"),
            (0xF193, "supplier ECU hardware version number"),
            (0xF194, "supplier ECU software number"),
            (0xF195, "supplier ECU software version number"),
            (0xF197, "system name or engine type"),
            (0xF19E, "ODX file identifier"),
        ];
        for (id, name) in names {
            d.dids.insert(
                id,
                DidInfo {
                    name: name.into(),
                    length: (id == 0xF190).then_some(17),
                    kind: if id == 0xF18B {
                        ValueKind::Bytes
                    } else {
                        ValueKind::Ascii
                    },
                },
            );
        }
        d
    }

    /// A DID's length, if known.
    pub fn did_length(&self, id: u16) -> Option<usize> {
        self.dids.get(&id).and_then(|d| d.length)
    }

    /// A DID's value as people read it (hex when the DID is unknown).
    pub fn show(&self, id: u16, value: &[u8]) -> String {
        match self.dids.get(&id) {
            Some(info) => info.kind.show(value),
            None => hex(value),
        }
    }
}

impl ValueKind {
    /// The value as people read it; bytes that do not fit the kind show as hex.
    pub fn show(&self, value: &[u8]) -> String {
        match self {
            ValueKind::Ascii => String::from_utf8_lossy(value)
                .trim_end_matches(['\0', ' '])
                .to_string(),
            ValueKind::Bytes => hex(value),
            ValueKind::Number {
                signed,
                scale,
                offset,
                unit,
            } => match number(value, *signed) {
                Some(raw) => with_unit(raw * scale + offset, unit),
                None => hex(value),
            },
            ValueKind::Array {
                width,
                signed,
                scale,
                unit,
            } => {
                if *width == 0 || !value.len().is_multiple_of(*width) {
                    return hex(value);
                }
                let parts: Vec<String> = value
                    .chunks_exact(*width)
                    .map(|c| {
                        number(c, *signed).map_or_else(|| hex(c), |raw| fmt_number(raw * scale))
                    })
                    .collect();
                let joined = parts.join(", ");
                if unit.is_empty() {
                    format!("[{joined}]")
                } else {
                    format!("[{joined}] {unit}")
                }
            }
        }
    }
}

/// A big-endian number of 1 to 8 bytes.
#[allow(clippy::cast_precision_loss, clippy::cast_possible_wrap)]
fn number(bytes: &[u8], signed: bool) -> Option<f64> {
    if bytes.is_empty() || bytes.len() > 8 {
        return None;
    }
    let raw = bytes.iter().fold(0u64, |acc, b| acc << 8 | u64::from(*b));
    let bits = 8 * u32::try_from(bytes.len()).ok()?;
    if signed && bits < 64 && raw >> (bits - 1) & 1 == 1 {
        Some((raw as i64 - (1i64 << bits)) as f64)
    } else if signed {
        Some(raw as i64 as f64)
    } else {
        Some(raw as f64)
    }
}

fn fmt_number(value: f64) -> String {
    // Whole numbers without a fraction; others with what a scale of 0.01 or 0.1 needs.
    if value == libm::trunc(value) && value.abs() < 1e15 {
        format!("{value:.0}")
    } else {
        let text = format!("{value:.4}");
        text.trim_end_matches('0').trim_end_matches('.').to_string()
    }
}

fn with_unit(value: f64, unit: &str) -> String {
    if unit.is_empty() {
        fmt_number(value)
    } else {
        format!("{} {unit}", fmt_number(value))
    }
}

/// Bytes as lower-case hex without separators.
pub fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// A DTC in the SAE J2012 / ISO 15031-6 form: its system letter, four characters, and the
/// failure type byte (`0xC07300` → `U0073-00`).
pub fn dtc_code(dtc: u32) -> String {
    let [_, high, low, failure_type] = dtc.to_be_bytes();
    let system = match high >> 6 {
        0 => 'P',
        1 => 'C',
        2 => 'B',
        _ => 'U',
    };
    format!(
        "{system}{}{:X}{low:02X}-{failure_type:02X}",
        (high >> 4) & 0x3,
        high & 0x0F
    )
}

/// The names of the status bits set in `status` (ISO 14229-1 D.2).
pub fn status_bits(bits: u8) -> Vec<&'static str> {
    [
        (status::TEST_FAILED, "testFailed"),
        (
            status::TEST_FAILED_THIS_CYCLE,
            "testFailedThisOperationCycle",
        ),
        (status::PENDING, "pendingDTC"),
        (status::CONFIRMED, "confirmedDTC"),
        (
            status::NOT_COMPLETED_SINCE_CLEAR,
            "testNotCompletedSinceLastClear",
        ),
        (status::FAILED_SINCE_CLEAR, "testFailedSinceLastClear"),
        (
            status::NOT_COMPLETED_THIS_CYCLE,
            "testNotCompletedThisOperationCycle",
        ),
        (status::WARNING_INDICATOR, "warningIndicatorRequested"),
    ]
    .into_iter()
    .filter(|(bit, _)| bits & bit != 0)
    .map(|(_, name)| name)
    .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dtcs_print_as_j2012_codes() {
        assert_eq!(dtc_code(0xC07300), "U0073-00");
        assert_eq!(dtc_code(0x512300), "C1123-00");
        assert_eq!(dtc_code(0x01_2345), "P0123-45");
        assert_eq!(dtc_code(0x9A_BC01), "B1ABC-01");
    }

    #[test]
    fn values_read_by_kind() {
        let number = |signed, scale, unit: &str| ValueKind::Number {
            signed,
            scale,
            offset: 0.0,
            unit: unit.into(),
        };
        assert_eq!(number(true, 0.01, "deg").show(&[0xFF, 0x38]), "-2 deg");
        assert_eq!(number(false, 0.1, "V").show(&[0x03, 0x2A]), "81 V");
        assert_eq!(number(false, 0.1, "V").show(&[0x03, 0x2B]), "81.1 V");
        assert_eq!(number(false, 1.0, "").show(&[]), "");
        assert_eq!(ValueKind::Ascii.show(b"1.4.0\0\0"), "1.4.0");
        let array = ValueKind::Array {
            width: 2,
            signed: true,
            scale: 0.01,
            unit: "deg".into(),
        };
        assert_eq!(array.show(&[0, 50, 0xFF, 0xCE]), "[0.5, -0.5] deg");
        assert_eq!(array.show(&[1, 2, 3]), "010203");
        assert_eq!(status_bits(0x09), ["testFailed", "confirmedDTC"].to_vec());
    }
}
