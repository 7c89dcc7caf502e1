//! Bus specs: one string a user can type names any bus.

use std::fmt;
use std::str::FromStr;

use crate::Bus;

/// A parsed bus spec.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum BusSpec {
    /// `virtual:NAME`: the in-process bus called NAME.
    Virtual {
        /// The bus's name.
        name: String,
    },
}

/// A spec that names no bus, with what is wrong.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SpecError {
    /// No `scheme:` prefix.
    #[error("'{0}' is not a bus spec: expected SCHEME:PARAMETERS, e.g. virtual:test")]
    NoScheme(String),
    /// A scheme no backend handles.
    #[error("unknown bus scheme '{scheme}' (known: {known})")]
    UnknownScheme {
        /// The scheme given.
        scheme: String,
        /// The schemes there are.
        known: &'static str,
    },
    /// Parameters the scheme does not accept.
    #[error("{scheme}: {reason}")]
    Parameters {
        /// The scheme.
        scheme: &'static str,
        /// What is wrong.
        reason: String,
    },
}

const KNOWN: &str = "virtual";

impl FromStr for BusSpec {
    type Err = SpecError;

    fn from_str(text: &str) -> Result<BusSpec, SpecError> {
        let (scheme, rest) = text
            .split_once(':')
            .ok_or_else(|| SpecError::NoScheme(text.to_string()))?;
        match scheme {
            "virtual" => {
                let valid = !rest.is_empty()
                    && rest
                        .chars()
                        .all(|c| c.is_ascii_alphanumeric() || "-_.".contains(c));
                if !valid {
                    return Err(SpecError::Parameters {
                        scheme: "virtual",
                        reason: format!(
                            "'{rest}' is not a bus name (letters, digits, '-', '_', '.')"
                        ),
                    });
                }
                Ok(BusSpec::Virtual {
                    name: rest.to_string(),
                })
            }
            other => Err(SpecError::UnknownScheme {
                scheme: other.to_string(),
                known: KNOWN,
            }),
        }
    }
}

impl fmt::Display for BusSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            BusSpec::Virtual { name } => write!(f, "virtual:{name}"),
        }
    }
}

/// Open the bus a spec names.
pub fn open(spec: &str) -> Result<Box<dyn Bus>, SpecError> {
    match spec.parse::<BusSpec>()? {
        BusSpec::Virtual { name } => Ok(Box::new(crate::virtual_bus::VirtualBus::join(&name))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn specs_parse_and_refuse_clearly() {
        assert_eq!(
            "virtual:test-1".parse(),
            Ok(BusSpec::Virtual {
                name: "test-1".into()
            })
        );
        assert_eq!(
            "virtual:test-1".parse::<BusSpec>().unwrap().to_string(),
            "virtual:test-1"
        );
        assert!(matches!(
            "can0".parse::<BusSpec>(),
            Err(SpecError::NoScheme(_))
        ));
        let e = "carrier:pigeon".parse::<BusSpec>().unwrap_err();
        assert_eq!(
            e.to_string(),
            "unknown bus scheme 'carrier' (known: virtual)"
        );
        assert!(matches!(
            "virtual:".parse::<BusSpec>(),
            Err(SpecError::Parameters { .. })
        ));
        assert!(matches!(
            "virtual:a b".parse::<BusSpec>(),
            Err(SpecError::Parameters { .. })
        ));
    }
}
