//! Why data cannot be protected or checked, for every profile.

/// Why data cannot be protected or checked.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum E2eError {
    /// The buffer is shorter than the configured length, or the length is below 2.
    #[error("protected data needs {needed} bytes, buffer has {actual}")]
    Length {
        /// Bytes needed.
        needed: usize,
        /// Bytes there.
        actual: usize,
    },
}
