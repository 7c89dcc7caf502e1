//! `bywire uds --describe FILE`: what a tester knows of an ECU, from a TOML file (or `tug`,
//! the reference tug's vehicle control ECU):
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

use std::collections::BTreeMap;

use anyhow::{anyhow, bail, Context, Result};
use bywire_diag::describe::{Description, DidInfo, ValueKind};

use crate::support::numbers::hex;
use serde::Deserialize;

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

/// The description `spec` names: `tug`, or a TOML file.
pub fn load(spec: &str) -> Result<Description> {
    if spec == "tug" {
        return Ok(bywire_tug::diagnostics::description());
    }
    let text = std::fs::read_to_string(spec).with_context(|| format!("--describe {spec}"))?;
    parse(&text).with_context(|| format!("--describe {spec}"))
}

fn parse(text: &str) -> Result<Description> {
    let raw: RawDescription =
        toml::from_str(text).map_err(|e| anyhow!("{}", e.to_string().trim_end()))?;
    let mut d = Description::default();
    for (id, did) in raw.did {
        let key =
            hex::<u16>(&id).ok_or_else(|| anyhow!("[did.{id}]: not a hex data identifier"))?;
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
                    other => bail!("[did.{id}] width {other:?}: 1, 2 or 4 bytes per element"),
                },
                signed: did.signed,
                scale: did.scale,
                unit: did.unit,
            },
            other => {
                bail!("[did.{id}] kind '{other}': one of ascii, bytes, unsigned, signed, array")
            }
        };
        if matches!(kind, ValueKind::Number { .. })
            && did.length.is_none_or(|l| !(1..=8).contains(&l))
        {
            bail!("[did.{id}]: a number needs a length of 1 to 8 bytes");
        }
        d.dids.insert(
            key,
            DidInfo {
                name: did.name,
                length: did.length,
                kind,
            },
        );
    }
    for (code, name) in raw.dtc {
        let dtc = hex::<u32>(&code)
            .filter(|d| *d <= 0xFF_FFFF)
            .ok_or_else(|| anyhow!("[dtc] {code}: not a 24-bit hex DTC"))?;
        d.dtcs.insert(dtc, name);
    }
    Ok(d)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    #[test]
    fn a_description_file_reads_and_its_mistakes_are_named() {
        let d = parse(
            "[did.F190]\nname = \"VIN\"\nlength = 17\nkind = \"ascii\"\n\
             [did.DD01]\nname = \"speed\"\nlength = 2\nkind = \"signed\"\nscale = 0.01\nunit = \"m/s\"\n\
             [dtc]\nC07300 = \"bus-off\"\n",
        )
        .unwrap();
        assert_eq!(d.did_length(0xF190), Some(17));
        assert_eq!(d.show(0xDD01, &[0xFF, 0x9C]), "-1 m/s");
        assert_eq!(d.dtcs[&0xC07300], "bus-off");
        for (text, what) in [
            ("[did.XYZ]\nname = \"a\"\n", "[did.XYZ]: not a hex"),
            (
                "[did.0101]\nname = \"a\"\nkind = \"float\"\n",
                "kind 'float'",
            ),
            (
                "[did.0101]\nname = \"a\"\nkind = \"unsigned\"\n",
                "length of 1 to 8",
            ),
            ("[dtc]\n1000000 = \"x\"\n", "not a 24-bit"),
            ("[did.0101]\nnam = \"a\"\n", "unknown field"),
        ] {
            let error = format!("{:#}", parse(text).unwrap_err());
            assert!(error.contains(what), "{error} ({what})");
        }
    }
}
