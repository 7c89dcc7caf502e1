//! SecOC declared on a message, by message attributes (as the counter and checksum are
//! declared on signals, [`crate::e2e`]):
//!
//! ```text
//! BA_DEF_ BO_ "SecOCDataId" INT 0 65535;                the data ID; marks the message secured
//! BA_DEF_ BO_ "SecOCProfile" STRING;                    an AUTOSAR profile, e.g. "24Bit-CMAC-8Bit-FV"
//! BA_DEF_ BO_ "SecOCFreshnessValueLength" INT 0 64;     or the three lengths, in bits
//! BA_DEF_ BO_ "SecOCFreshnessValueTxLength" INT 0 64;
//! BA_DEF_ BO_ "SecOCAuthInfoTxLength" INT 1 128;
//! BA_DEF_ BO_ "SecOCAuthenticPduLength" INT 0 64;       optional: the authentic payload's bytes
//! BA_DEF_ BO_ "SecOCKeyId" INT 0 65535;                 optional: the key's id in the key file (0)
//! ```
//!
//! The authentic payload is, unless declared, the message's length less the bytes the
//! freshness and MAC bits take; the signals must lie within it (the MAC covers only it).
//! Each attribute is read from the message itself: a database-wide default would secure
//! every message with one data ID, which is never meant.

use bywire_secoc::{profile, Layout, LayoutError};

use crate::model::{AttrValue, Message, Num};

/// A message's SecOC declaration.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Secured {
    /// Where the parts are and what the MAC covers.
    pub layout: Layout,
    /// The key's id in the key file.
    pub key_id: u32,
}

/// Why a message's SecOC declaration is unusable.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum SecuredError {
    /// An attribute with a value of the wrong kind or range.
    #[error("message {message}: attribute {attribute} must be {expected}")]
    Attribute {
        /// The message.
        message: String,
        /// The attribute.
        attribute: &'static str,
        /// What it must be.
        expected: &'static str,
    },
    /// A profile not known.
    #[error("message {message}: SecOCProfile \"{profile}\" is not a known profile ({known})")]
    Profile {
        /// The message.
        message: String,
        /// The name given.
        profile: String,
        /// The profiles known.
        known: String,
    },
    /// Neither a profile nor all three lengths.
    #[error(
        "message {message}: SecOCDataId without SecOCProfile or all of SecOCFreshnessValueLength, \
         SecOCFreshnessValueTxLength and SecOCAuthInfoTxLength"
    )]
    Lengths {
        /// The message.
        message: String,
    },
    /// The lengths do not fit together or in the message.
    #[error("message {message}: {error}")]
    Layout {
        /// The message.
        message: String,
        /// Why.
        error: LayoutError,
    },
    /// The authenticator does not fit in the message's length.
    #[error(
        "message {message}: {needed} bytes of payload, freshness and MAC do not fit in its {size}"
    )]
    Size {
        /// The message.
        message: String,
        /// Bytes needed.
        needed: usize,
        /// The message's length.
        size: u32,
    },
}

fn int(message: &Message, attribute: &'static str, max: i128) -> Result<Option<u32>, SecuredError> {
    match message.attribute(attribute) {
        None => Ok(None),
        Some(AttrValue::Number(Num::Int(v))) if (0..=max).contains(v) => Ok(u32::try_from(*v).ok()),
        Some(_) => Err(SecuredError::Attribute {
            message: message.name.clone(),
            attribute,
            expected: match max {
                64 => "an integer from 0 to 64",
                128 => "an integer from 0 to 128",
                _ => "an integer from 0 to 65535",
            },
        }),
    }
}

impl Secured {
    /// The message's declaration; `None` when it is not secured.
    pub fn of(message: &Message) -> Result<Option<Secured>, SecuredError> {
        let Some(data_id) = int(message, "SecOCDataId", 65535)? else {
            return Ok(None);
        };
        let lengths = match message.attribute("SecOCProfile") {
            Some(AttrValue::Str(name)) => {
                let p = profile(name).ok_or_else(|| SecuredError::Profile {
                    message: message.name.clone(),
                    profile: name.clone(),
                    known: bywire_secoc::PROFILES
                        .iter()
                        .map(|p| p.name)
                        .collect::<Vec<_>>()
                        .join(", "),
                })?;
                (p.fv_length, p.fv_tx_length, p.mac_tx_length)
            }
            Some(_) => {
                return Err(SecuredError::Attribute {
                    message: message.name.clone(),
                    attribute: "SecOCProfile",
                    expected: "a string",
                })
            }
            None => match (
                int(message, "SecOCFreshnessValueLength", 64)?,
                int(message, "SecOCFreshnessValueTxLength", 64)?,
                int(message, "SecOCAuthInfoTxLength", 128)?,
            ) {
                (Some(fv), Some(tx), Some(mac)) => (fv, tx, mac),
                _ => {
                    return Err(SecuredError::Lengths {
                        message: message.name.clone(),
                    })
                }
            },
        };
        let (fv_length, fv_tx_length, mac_tx_length) = lengths;
        let authenticator =
            usize::try_from((fv_tx_length + mac_tx_length).div_ceil(8)).unwrap_or(0);
        let size = usize::try_from(message.size).unwrap_or(usize::MAX);
        let payload_length = match int(message, "SecOCAuthenticPduLength", 64)? {
            Some(n) => usize::try_from(n).unwrap_or(usize::MAX),
            None => size.checked_sub(authenticator).ok_or(SecuredError::Size {
                message: message.name.clone(),
                needed: authenticator,
                size: message.size,
            })?,
        };
        let layout = Layout::new(
            u16::try_from(data_id).unwrap_or(0),
            payload_length,
            fv_length,
            fv_tx_length,
            mac_tx_length,
        )
        .map_err(|error| SecuredError::Layout {
            message: message.name.clone(),
            error,
        })?;
        if layout.secured_length() > size {
            return Err(SecuredError::Size {
                message: message.name.clone(),
                needed: layout.secured_length(),
                size: message.size,
            });
        }
        let key_id = int(message, "SecOCKeyId", 65535)?.unwrap_or(0);
        Ok(Some(Secured { layout, key_id }))
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::indexing_slicing)]

    use super::*;
    use crate::{parse_str, Mode};

    const DEFS: &str = "BA_DEF_ BO_ \"SecOCDataId\" INT 0 65535;\nBA_DEF_ BO_ \"SecOCProfile\" STRING;\n\
BA_DEF_ BO_ \"SecOCFreshnessValueLength\" INT 0 64;\nBA_DEF_ BO_ \"SecOCFreshnessValueTxLength\" INT 0 64;\n\
BA_DEF_ BO_ \"SecOCAuthInfoTxLength\" INT 0 128;\nBA_DEF_ BO_ \"SecOCAuthenticPduLength\" INT 0 64;\n\
BA_DEF_ BO_ \"SecOCKeyId\" INT 0 65535;\n\
BO_ 256 Command: 8 ADS\n SG_ Steering : 0|16@1- (0.001,0) [-1|1] \"rad\" ECU\n SG_ Speed : 16|16@1+ (0.01,0) [0|10] \"m/s\" ECU\n\
BO_ 512 Wide: 16 ADS\n SG_ Value : 0|32@1+ (1,0) [0|0] \"\" ECU\n\
BO_ 768 Plain: 8 ADS\n SG_ Value : 0|8@1+ (1,0) [0|0] \"\" ECU\n";

    fn secured(attributes: &str, index: usize) -> Result<Option<Secured>, SecuredError> {
        let (db, diags) = parse_str(&format!("{DEFS}{attributes}"), Mode::Strict).unwrap();
        assert!(diags.is_empty(), "{diags:?}");
        Secured::of(&db.messages[index])
    }

    #[test]
    fn a_profile_or_three_lengths_declare_a_secured_message() {
        let s = secured(
            "BA_ \"SecOCDataId\" BO_ 256 4660;\nBA_ \"SecOCProfile\" BO_ 256 \"24Bit-CMAC-8Bit-FV\";\n",
            0,
        )
        .unwrap()
        .unwrap();
        assert_eq!(s.layout, Layout::new(0x1234, 4, 8, 8, 24).unwrap());
        assert_eq!(s.key_id, 0);
        let s = secured(
            "BA_ \"SecOCDataId\" BO_ 512 7;\nBA_ \"SecOCFreshnessValueLength\" BO_ 512 32;\n\
             BA_ \"SecOCFreshnessValueTxLength\" BO_ 512 4;\nBA_ \"SecOCAuthInfoTxLength\" BO_ 512 28;\n\
             BA_ \"SecOCAuthenticPduLength\" BO_ 512 4;\nBA_ \"SecOCKeyId\" BO_ 512 2;\n",
            1,
        )
        .unwrap()
        .unwrap();
        assert_eq!(s.layout, Layout::new(7, 4, 32, 4, 28).unwrap());
        assert_eq!(s.key_id, 2);
        assert_eq!(secured("", 2).unwrap(), None);
    }

    #[test]
    fn unusable_declarations_name_the_message_and_what_is_wrong() {
        for (attributes, expected) in [
            (
                "BA_ \"SecOCDataId\" BO_ 256 1;\n",
                "message Command: SecOCDataId without SecOCProfile or all of",
            ),
            (
                "BA_ \"SecOCDataId\" BO_ 256 1;\nBA_ \"SecOCProfile\" BO_ 256 \"64Bit-Magic\";\n",
                "message Command: SecOCProfile \"64Bit-Magic\" is not a known profile (24Bit-CMAC-8Bit-FV, 24Bit-CMAC-No-FV)",
            ),
            (
                "BA_ \"SecOCDataId\" BO_ 256 1;\nBA_ \"SecOCFreshnessValueLength\" BO_ 256 8;\n\
                 BA_ \"SecOCFreshnessValueTxLength\" BO_ 256 16;\nBA_ \"SecOCAuthInfoTxLength\" BO_ 256 24;\n",
                "message Command: 16 freshness bits sent of a freshness value of 8 bits",
            ),
            (
                "BA_ \"SecOCDataId\" BO_ 256 1;\nBA_ \"SecOCFreshnessValueLength\" BO_ 256 8;\n\
                 BA_ \"SecOCFreshnessValueTxLength\" BO_ 256 8;\nBA_ \"SecOCAuthInfoTxLength\" BO_ 256 24;\n\
                 BA_ \"SecOCAuthenticPduLength\" BO_ 256 6;\n",
                "message Command: 10 bytes of payload, freshness and MAC do not fit in its 8",
            ),
        ] {
            let error = secured(attributes, 0).unwrap_err().to_string();
            assert!(error.starts_with(expected), "{error}");
        }
    }
}
