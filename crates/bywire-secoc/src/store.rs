//! A sender's freshness kept across restarts, so that a restart is not a rewind.
//!
//! The file holds one decimal number: a freshness value no message has been signed with, at
//! or above every value used. Values are reserved ahead, `step` at a time (one write per
//! `step` messages, not one per message), and each reservation is written before any value in
//! it is used: to a temporary file, synced, renamed over the old one, the directory synced. A
//! kill or power loss leaves the old reservation or the new one, never a torn file; at worst a
//! restart skips the unused rest of a reservation, and it never reuses a value.
//!
//! A file that is there but does not hold a number is an error, not a fresh start: starting
//! again from 1 would be exactly the rewind the file exists to prevent.

use std::fmt;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Why the freshness file cannot be used.
#[derive(Debug)]
#[non_exhaustive]
pub enum StoreError {
    /// Reading or writing failed.
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The file holds no freshness value.
    Corrupt {
        /// The file.
        path: PathBuf,
    },
    /// Every value has been used (a new key is needed).
    Exhausted {
        /// The file.
        path: PathBuf,
    },
}

impl fmt::Display for StoreError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            StoreError::Io { path, source } => write!(f, "{}: {source}", path.display()),
            StoreError::Corrupt { path } => write!(
                f,
                "{}: not a whole freshness value (damaged, or a write torn short; refusing to \
                 start over: that would be a rewind)",
                path.display()
            ),
            StoreError::Exhausted { path } => write!(
                f,
                "{}: every freshness value has been used (a new key is needed)",
                path.display()
            ),
        }
    }
}

// The OS error's text is in the message already: no source, or `{:#}` would say it twice.
impl std::error::Error for StoreError {}

/// A sender's persisted freshness.
#[derive(Debug)]
pub struct FreshnessStore {
    path: PathBuf,
    /// Values below this may be used without another write.
    reserved: u64,
    step: u64,
}

impl FreshnessStore {
    /// Open (or create) the store at `path`, reserving `step` values (at least 1) at a time;
    /// the first freshness value to use (1 for a new file).
    pub fn open(path: &Path, step: u64) -> Result<(FreshnessStore, u64), StoreError> {
        let start = match std::fs::read_to_string(path) {
            // Written whole as `DIGITS\n`: without its newline it is a torn write (`12` of
            // `1280`), refused like any other damage.
            Ok(text) => text
                .strip_suffix('\n')
                .filter(|digits| !digits.is_empty() && digits.bytes().all(|b| b.is_ascii_digit()))
                .and_then(|digits| digits.parse::<u64>().ok())
                .ok_or_else(|| StoreError::Corrupt {
                    path: path.to_path_buf(),
                })?,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => 1,
            Err(source) => {
                return Err(StoreError::Io {
                    path: path.to_path_buf(),
                    source,
                })
            }
        };
        let mut store = FreshnessStore {
            path: path.to_path_buf(),
            reserved: start,
            step: step.max(1),
        };
        store.reserve_from(start)?;
        Ok((store, start))
    }

    /// Call before signing with `freshness`: writes the next reservation when it is due.
    pub fn before_signing(&mut self, freshness: u64) -> Result<(), StoreError> {
        if freshness < self.reserved {
            return Ok(());
        }
        self.reserve_from(freshness)
    }

    /// Values from `from` up to `from + step` may be used once this returns.
    fn reserve_from(&mut self, from: u64) -> Result<(), StoreError> {
        let until = from.checked_add(self.step).ok_or(StoreError::Exhausted {
            path: self.path.clone(),
        })?;
        write_atomically(&self.path, format!("{until}\n").as_bytes()).map_err(|source| {
            StoreError::Io {
                path: self.path.clone(),
                source,
            }
        })?;
        self.reserved = until;
        Ok(())
    }
}

/// Write `bytes` to `path` so that it holds either its old content or all of the new.
fn write_atomically(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let mut temporary = path.as_os_str().to_owned();
    temporary.push(".tmp");
    let temporary = PathBuf::from(temporary);
    {
        let mut file = std::fs::File::create(&temporary)?;
        file.write_all(bytes)?;
        file.sync_all()?;
    }
    std::fs::rename(&temporary, path)?;
    if let Some(directory) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::File::open(directory)?.sync_all()?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    /// A store's path in an empty folder for one test, removed with the folder.
    fn temp(name: &str) -> (tempfile::TempDir, PathBuf) {
        let dir = tempfile::Builder::new()
            .prefix(&format!("bywire-secoc-{name}-"))
            .tempdir()
            .unwrap();
        let path = dir.path().join("freshness");
        (dir, path)
    }

    #[test]
    fn a_restart_goes_on_past_every_value_used() {
        let (_dir, path) = temp("restart");
        let (mut store, start) = FreshnessStore::open(&path, 100).unwrap();
        assert_eq!(start, 1);
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "101\n");
        for fv in start..=250 {
            store.before_signing(fv).unwrap();
        }
        // 250 used: the reservation covers it.
        let reserved: u64 = std::fs::read_to_string(&path)
            .unwrap()
            .trim()
            .parse()
            .unwrap();
        assert!(reserved > 250, "{reserved}");
        drop(store);
        let (_, start) = FreshnessStore::open(&path, 100).unwrap();
        assert_eq!(start, reserved);
        assert!(!path.with_extension("tmp").exists());
    }

    #[test]
    fn a_damaged_file_is_refused_not_started_over() {
        let (_dir, path) = temp("damaged");
        // Damaged, or torn short: "12" of "1280\n" has no newline.
        for damaged in ["12x\n", "12", "", "\n", " 12\n", "12\0\0"] {
            std::fs::write(&path, damaged).unwrap();
            let error = FreshnessStore::open(&path, 10).err().unwrap().to_string();
            assert!(
                error.contains("refusing to start over"),
                "{damaged:?}: {error}"
            );
        }
        std::fs::write(&path, format!("{}\n", u64::MAX - 5)).unwrap();
        let error = FreshnessStore::open(&path, 10).err().unwrap().to_string();
        assert!(
            error.contains("every freshness value has been used"),
            "{error}"
        );
    }

    #[test]
    fn a_store_that_cannot_be_read_or_written_names_its_file_and_why() {
        let (dir, path) = temp("unwritable");
        // A folder where the file should be: it cannot be read as one.
        std::fs::create_dir(&path).unwrap();
        let error = FreshnessStore::open(&path, 10).err().unwrap();
        assert!(matches!(error, StoreError::Io { .. }), "{error:?}");
        assert!(
            error.to_string().starts_with(&path.display().to_string()),
            "{error}"
        );
        // A store whose folder went away: the next reservation cannot be written, and the
        // values it would have covered are not used.
        let path = dir.path().join("sub").join("freshness");
        std::fs::create_dir(path.parent().unwrap()).unwrap();
        let (mut store, start) = FreshnessStore::open(&path, 2).unwrap();
        store.before_signing(start + 1).unwrap();
        std::fs::remove_dir_all(path.parent().unwrap()).unwrap();
        let error = store.before_signing(start + 2).err().unwrap();
        assert!(matches!(error, StoreError::Io { .. }), "{error:?}");
        assert!(error.to_string().contains("freshness"), "{error}");
    }
}
