//! How a configuration file says what is wrong with it: the file, then either what its reader
//! said (TOML or YAML syntax, a key the schema does not have, with line and column) or the key
//! whose value is wrong and why. One type for every file the stack reads (CANopen bus
//! descriptions, vehicle profiles, simulator scenarios, UDS ECU descriptions), so a tool
//! shows and matches them one way.
//!
//! ```
//! use bywire_core::FileError;
//! let error = FileError::invalid("bus.toml", "node.steer.mode", "not a CiA 402 mode");
//! assert_eq!(error.to_string(), "bus.toml: node.steer.mode: not a CiA 402 mode");
//! assert_eq!(error.key(), Some("node.steer.mode"));
//! ```

use alloc::string::{String, ToString};

/// Why a configuration file was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum FileError {
    /// The file could not be read, or is not of its schema's shape.
    #[error("{file}: {message}")]
    Syntax {
        /// The file.
        file: String,
        /// What its reader said, with line and column where it has them.
        message: String,
    },
    /// A value is out of range or inconsistent with another.
    #[error("{file}: {key}: {reason}")]
    Invalid {
        /// The file.
        file: String,
        /// The key, dotted (`node.steer.mode`).
        key: String,
        /// Why.
        reason: String,
    },
}

impl FileError {
    /// A file that does not read as its schema.
    pub fn syntax(file: impl ToString, message: impl ToString) -> FileError {
        FileError::Syntax {
            file: file.to_string(),
            message: message.to_string(),
        }
    }

    /// A key whose value is wrong.
    pub fn invalid(file: impl ToString, key: impl ToString, reason: impl ToString) -> FileError {
        FileError::Invalid {
            file: file.to_string(),
            key: key.to_string(),
            reason: reason.to_string(),
        }
    }

    /// The file.
    pub fn file(&self) -> &str {
        match self {
            FileError::Syntax { file, .. } | FileError::Invalid { file, .. } => file,
        }
    }

    /// The key whose value is wrong, if that is the problem.
    pub fn key(&self) -> Option<&str> {
        match self {
            FileError::Invalid { key, .. } => Some(key),
            FileError::Syntax { .. } => None,
        }
    }
}
