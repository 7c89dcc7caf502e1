//! Key files: one 128-bit key per key id, as hex, in a file only its owner can read.
//!
//! ```text
//! # comments and blank lines are skipped
//! 2b7e151628aed2a6abf7158809cf4f3c        a key alone is key id 0 (the only line then)
//! 1 000102030405060708090a0b0c0d0e0f      or: KEY_ID HEX, the id in decimal or 0x hex
//! ```
//!
//! A file that its group or others may read or write is refused (as ssh refuses such a private
//! key): a key others can read authenticates nothing. No error and no `Debug` output shows a
//! key or any part of the line it was on.

use std::fmt;
use std::path::{Path, PathBuf};

use crate::Key;

/// Why a key file cannot be used.
#[derive(Debug)]
#[non_exhaustive]
pub enum KeyFileError {
    /// It cannot be read.
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// Its group or others may read or write it.
    Permissions {
        /// The file.
        path: PathBuf,
        /// Its mode bits.
        mode: u32,
    },
    /// It belongs to another user than the one reading it.
    Owner {
        /// The file.
        path: PathBuf,
        /// Its owner's user id.
        owner: u32,
        /// The reading process's effective user id.
        user: u32,
    },
    /// A line that is not a key.
    Line {
        /// The file.
        path: PathBuf,
        /// The line number, from 1.
        line: usize,
        /// What is wrong (never the line's text).
        why: &'static str,
    },
    /// Two keys with one id.
    Duplicate {
        /// The file.
        path: PathBuf,
        /// The second line.
        line: usize,
        /// The id.
        id: u32,
    },
    /// No key in it.
    Empty {
        /// The file.
        path: PathBuf,
    },
}

impl fmt::Display for KeyFileError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            KeyFileError::Io { path, source } => write!(f, "{}: {source}", path.display()),
            KeyFileError::Permissions { path, mode } => write!(
                f,
                "{}: the key file may be read or written by others (mode {:04o}); \
                 make it the owner's alone: chmod 600 {}",
                path.display(),
                mode & 0o7777,
                path.display()
            ),
            KeyFileError::Owner { path, owner, user } => write!(
                f,
                "{}: the key file belongs to user {owner}, not to this process's user {user}; \
                 a key file must be its user's own, as ssh asks of a private key: \
                 chown {user} {}",
                path.display(),
                path.display()
            ),
            KeyFileError::Line { path, line, why } => {
                write!(f, "{}:{line}: {why}", path.display())
            }
            KeyFileError::Duplicate { path, line, id } => {
                write!(f, "{}:{line}: key id {id} given twice", path.display())
            }
            KeyFileError::Empty { path } => write!(f, "{}: no key in the file", path.display()),
        }
    }
}

// The OS error's text is in the message already: no source, or `{:#}` would say it twice.
impl std::error::Error for KeyFileError {}

/// The keys of a key file.
#[derive(Clone)]
pub struct KeyFile {
    keys: Vec<(u32, Key)>,
}

impl fmt::Debug for KeyFile {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let ids: Vec<u32> = self.keys.iter().map(|(id, _)| *id).collect();
        write!(f, "KeyFile {{ ids: {ids:?} }}")
    }
}

impl KeyFile {
    /// Read `path`, refusing it when others may read or write it.
    pub fn load(path: &Path) -> Result<KeyFile, KeyFileError> {
        let io = |source| KeyFileError::Io {
            path: path.to_path_buf(),
            source,
        };
        let metadata = std::fs::metadata(path).map_err(io)?;
        #[cfg(unix)]
        {
            use std::os::unix::fs::{MetadataExt, PermissionsExt};
            let mode = metadata.permissions().mode();
            if mode & 0o077 != 0 {
                return Err(KeyFileError::Permissions {
                    path: path.to_path_buf(),
                    mode,
                });
            }
            let user = rustix::process::geteuid().as_raw();
            if metadata.uid() != user {
                return Err(KeyFileError::Owner {
                    path: path.to_path_buf(),
                    owner: metadata.uid(),
                    user,
                });
            }
        }
        #[cfg(not(unix))]
        let _ = metadata;
        let bytes = std::fs::read(path).map_err(io)?;
        KeyFile::parse(path, &bytes)
    }

    /// The keys in `text` (named `path` in errors).
    pub fn parse(path: &Path, text: &[u8]) -> Result<KeyFile, KeyFileError> {
        let line_error = |line, why| KeyFileError::Line {
            path: path.to_path_buf(),
            line,
            why,
        };
        let text = std::str::from_utf8(text).map_err(|_| line_error(1, "not text"))?;
        let mut keys: Vec<(u32, Key)> = Vec::new();
        let mut bare = false;
        for (index, raw) in text.lines().enumerate() {
            let line = index + 1;
            let content = raw.split('#').next().unwrap_or("").trim();
            if content.is_empty() {
                continue;
            }
            let mut words = content.split_whitespace();
            let (id, hex) = match (words.next(), words.next(), words.next()) {
                (Some(hex), None, None) => {
                    bare = true;
                    (0, hex)
                }
                (Some(id), Some(hex), None) => (
                    parse_id(id).ok_or_else(|| line_error(line, "the key id is not a number"))?,
                    hex,
                ),
                _ => return Err(line_error(line, "expected a key, or a key id and a key")),
            };
            let key = parse_key(hex)
                .ok_or_else(|| line_error(line, "a key is 32 hex digits (16 bytes)"))?;
            if keys.iter().any(|(known, _)| *known == id) || (bare && !keys.is_empty()) {
                return Err(KeyFileError::Duplicate {
                    path: path.to_path_buf(),
                    line,
                    id,
                });
            }
            keys.push((id, key));
        }
        if keys.is_empty() {
            return Err(KeyFileError::Empty {
                path: path.to_path_buf(),
            });
        }
        Ok(KeyFile { keys })
    }

    /// The key with `id`.
    pub fn key(&self, id: u32) -> Option<&Key> {
        self.keys.iter().find(|(k, _)| *k == id).map(|(_, key)| key)
    }

    /// The key ids in the file.
    pub fn ids(&self) -> impl Iterator<Item = u32> + '_ {
        self.keys.iter().map(|(id, _)| *id)
    }
}

fn parse_id(text: &str) -> Option<u32> {
    match text.strip_prefix("0x").or_else(|| text.strip_prefix("0X")) {
        Some(hex) => u32::from_str_radix(hex, 16).ok(),
        None => text.parse().ok(),
    }
}

fn parse_key(text: &str) -> Option<Key> {
    let digits = text.as_bytes();
    if digits.len() != 32 {
        return None;
    }
    let mut key = [0u8; 16];
    for (byte, pair) in key.iter_mut().zip(digits.chunks(2)) {
        let text = std::str::from_utf8(pair).ok()?;
        *byte = u8::from_str_radix(text, 16).ok()?;
    }
    Some(Key::new(key))
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::panic)]

    use super::*;

    const KEY: &str = "2b7e151628aed2a6abf7158809cf4f3c";

    fn parse(text: &str) -> Result<KeyFile, KeyFileError> {
        KeyFile::parse(Path::new("keys.txt"), text.as_bytes())
    }

    #[test]
    fn a_bare_key_is_id_0_and_ids_name_the_others() {
        let file = parse(&format!("# the ADS key\n{KEY}\n")).unwrap();
        assert!(file.key(0).is_some());
        let file = parse(&format!(
            "1 {KEY}\n0x10 000102030405060708090a0b0c0d0e0f # bus 2\n"
        ))
        .unwrap();
        assert_eq!(file.ids().collect::<Vec<_>>(), [1, 16]);
        assert!(file.key(0).is_none());
        assert_eq!(format!("{file:?}"), "KeyFile { ids: [1, 16] }");
    }

    #[test]
    fn errors_name_the_line_and_never_show_the_key() {
        let short = &KEY[..30];
        for (text, expected) in [
            (
                format!("1 {short}\n"),
                "keys.txt:1: a key is 32 hex digits (16 bytes)",
            ),
            (
                format!("\nx {KEY}\n"),
                "keys.txt:2: the key id is not a number",
            ),
            (
                format!("1 {KEY} extra\n"),
                "keys.txt:1: expected a key, or a key id and a key",
            ),
            (
                format!("1 {KEY}\n1 {KEY}\n"),
                "keys.txt:2: key id 1 given twice",
            ),
            (
                format!("{KEY}\n{KEY}\n"),
                "keys.txt:2: key id 0 given twice",
            ),
            ("# nothing\n".to_string(), "keys.txt: no key in the file"),
        ] {
            let error = parse(&text).err().unwrap().to_string();
            assert_eq!(error, expected);
            assert!(!error.contains(&KEY[..8]), "{error}");
        }
    }

    #[cfg(unix)]
    #[test]
    fn a_file_others_can_read_is_refused() {
        use std::os::unix::fs::PermissionsExt;
        let path = std::env::temp_dir().join(format!("bywire-secoc-keys-{}", std::process::id()));
        std::fs::write(&path, KEY).unwrap();
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o644)).unwrap();
        let error = KeyFile::load(&path).err().unwrap().to_string();
        assert!(
            error.contains("mode 0644") && error.contains("chmod 600"),
            "{error}"
        );
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o640)).unwrap();
        assert!(KeyFile::load(&path).is_err());
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o600)).unwrap();
        assert!(KeyFile::load(&path).unwrap().key(0).is_some());
        // Mode 0600 but another user's (only root can give a file away: as root, the test
        // does; otherwise it cannot make the case).
        let me = rustix::process::geteuid().as_raw();
        if me == 0 {
            std::os::unix::fs::chown(&path, Some(65534), None).unwrap();
            let error = KeyFile::load(&path).err().unwrap().to_string();
            assert!(
                error.contains("belongs to user 65534, not to this process's user 0")
                    && error.contains("chown 0"),
                "{error}"
            );
        }
        std::fs::remove_file(&path).unwrap();
        let error = KeyFile::load(&path).err().unwrap().to_string();
        assert!(error.contains("No such file"), "{error}");
    }
}
