//! An ECU's description as a tester reads it from a TOML file: its DIDs (name, length, how the
//! value reads) and its DTCs' names.
//!
//! ```toml
//! [did.F190]
//! name = "VIN"
//! length = 17
//! kind = "ascii"            # ascii, bytes, unsigned, signed, array
//!
//! [did.0200]
//! name = "steering offsets"
//! length = 8
//! kind = "array"
//! width = 2                 # bytes per element
//! signed = true
//! scale = 0.01
//! unit = "deg"
//!
//! [dtc]
//! C07300 = "bus 1 controller bus-off"
//! ```
//!
//! ```
//! use bywire_diag::describe::Description;
//! let text = "[did.F190]\nname = \"VIN\"\nlength = 17\nkind = \"ascii\"\n";
//! let d = Description::from_toml(text, "ecu.toml").unwrap();
//! assert_eq!(d.did_length(0xF190), Some(17));
//! let error = Description::from_toml("[did.F19X]\nname = \"VIN\"\n", "ecu.toml").unwrap_err();
//! assert_eq!(error.to_string(), "ecu.toml: did.F19X: not a hex data identifier");
//! ```

use alloc::collections::BTreeMap;
use alloc::string::{String, ToString};

use bywire_core::FileError;
use serde::Deserialize;

use crate::describe::{Description, DidInfo, ValueKind};

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDescription {
    #[serde(default)]
    did: BTreeMap<String, RawDid>,
    #[serde(default)]
    dtc: BTreeMap<String, String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDid {
    name: String,
    length: Option<usize>,
    #[serde(default = "bytes")]
    kind: String,
    #[serde(default)]
    signed: bool,
    #[serde(default = "one")]
    scale: f64,
    #[serde(default)]
    offset: f64,
    #[serde(default)]
    unit: String,
    width: Option<usize>,
}

fn bytes() -> String {
    "bytes".into()
}

fn one() -> f64 {
    1.0
}

/// A hex number of at most `max`, digits only (`from_str_radix` alone takes a sign).
fn hex(text: &str, max: u32) -> Option<u32> {
    if text.is_empty() || !text.bytes().all(|b| b.is_ascii_hexdigit()) {
        return None;
    }
    u32::from_str_radix(text, 16).ok().filter(|n| *n <= max)
}

impl Description {
    /// A description from a TOML file's text; `file` names it in errors, with the key whose
    /// value is wrong (`did.F190`, `dtc.C07300`).
    pub fn from_toml(text: &str, file: &str) -> Result<Description, FileError> {
        let raw: RawDescription = toml::from_str(text)
            .map_err(|e| FileError::syntax(file, e.to_string().trim_end().replace('\n', " ")))?;
        let mut d = Description::default();
        for (id, did) in raw.did {
            let key = alloc::format!("did.{id}");
            let invalid = |reason: &str| FileError::invalid(file, &key, reason);
            let number = hex(&id, 0xFFFF)
                .and_then(|n| u16::try_from(n).ok())
                .ok_or_else(|| invalid("not a hex data identifier"))?;
            let kind = match did.kind.as_str() {
                "ascii" => ValueKind::Ascii,
                "bytes" => ValueKind::Bytes,
                "unsigned" | "signed" => ValueKind::Number {
                    signed: did.kind == "signed" || did.signed,
                    scale: did.scale,
                    offset: did.offset,
                    unit: did.unit,
                },
                "array" => ValueKind::Array {
                    width: match did.width {
                        Some(w @ (1 | 2 | 4)) => w,
                        other => {
                            return Err(invalid(&alloc::format!(
                                "width {other:?}: 1, 2 or 4 bytes per element"
                            )))
                        }
                    },
                    signed: did.signed,
                    scale: did.scale,
                    unit: did.unit,
                },
                other => {
                    return Err(invalid(&alloc::format!(
                        "kind '{other}': one of ascii, bytes, unsigned, signed, array"
                    )))
                }
            };
            if matches!(kind, ValueKind::Number { .. })
                && did.length.is_none_or(|l| !(1..=8).contains(&l))
            {
                return Err(invalid("a number needs a length of 1 to 8 bytes"));
            }
            d.dids.insert(
                number,
                DidInfo {
                    name: did.name,
                    length: did.length,
                    kind,
                },
            );
        }
        for (code, name) in raw.dtc {
            let dtc = hex(&code, 0xFF_FFFF).ok_or_else(|| {
                FileError::invalid(file, alloc::format!("dtc.{code}"), "not a 24-bit hex DTC")
            })?;
            d.dtcs.insert(dtc, name);
        }
        Ok(d)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    #[test]
    fn a_description_file_reads_and_its_mistakes_are_named() {
        let d = Description::from_toml(
            "[did.F190]\nname = \"VIN\"\nlength = 17\nkind = \"ascii\"\n\
             [did.DD01]\nname = \"speed\"\nlength = 2\nkind = \"signed\"\nscale = 0.01\nunit = \"m/s\"\n\
             [dtc]\nC07300 = \"bus-off\"\n",
            "ecu.toml",
        )
        .unwrap();
        assert_eq!(d.did_length(0xF190), Some(17));
        assert_eq!(d.show(0xDD01, &[0xFF, 0x9C]), "-1 m/s");
        assert_eq!(d.dtcs[&0xC07300], "bus-off");
        for (text, key, what) in [
            ("[did.XYZ]\nname = \"a\"\n", Some("did.XYZ"), "not a hex"),
            (
                "[did.\"+101\"]\nname = \"a\"\n",
                Some("did.+101"),
                "not a hex",
            ),
            (
                "[did.0101]\nname = \"a\"\nkind = \"float\"\n",
                Some("did.0101"),
                "kind 'float'",
            ),
            (
                "[did.0101]\nname = \"a\"\nkind = \"unsigned\"\n",
                Some("did.0101"),
                "length of 1 to 8",
            ),
            (
                "[dtc]\n1000000 = \"x\"\n",
                Some("dtc.1000000"),
                "not a 24-bit",
            ),
            ("[did.0101]\nnam = \"a\"\n", None, "unknown field"),
        ] {
            let error = Description::from_toml(text, "ecu.toml").unwrap_err();
            assert_eq!(error.key(), key, "{error}");
            assert_eq!(error.file(), "ecu.toml");
            assert!(error.to_string().contains(what), "{error} ({what})");
        }
    }
}
