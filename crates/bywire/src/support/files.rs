//! Files written whole or not at all.

use std::path::Path;

use anyhow::{anyhow, Context, Result};

/// Render into a temporary file beside `path`, then rename it into place.
pub(crate) fn write_atomically(
    path: &Path,
    render: impl FnOnce(&Path) -> Result<()>,
) -> Result<()> {
    let name = path
        .file_name()
        .ok_or_else(|| anyhow!("-o {}: not a file name", path.display()))?
        .to_string_lossy();
    let extension = path
        .extension()
        .map_or(String::new(), |e| e.to_string_lossy().into_owned());
    let tmp = path.with_file_name(format!(".{name}.{}.tmp.{extension}", std::process::id()));
    let result = render(&tmp).and_then(|()| {
        std::fs::rename(&tmp, path).with_context(|| format!("cannot write {}", path.display()))
    });
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// Render a directory (a dataset) into a temporary directory beside `path`, then rename it
/// into place. `path` must not exist, or be an empty directory: a dataset is never mixed
/// with files of another run.
pub(crate) fn write_dir_atomically<T>(
    path: &Path,
    render: impl FnOnce(&Path) -> Result<T>,
) -> Result<T> {
    if let Ok(mut entries) = std::fs::read_dir(path) {
        if entries.next().is_some() {
            return Err(anyhow!(
                "{}: the directory exists and is not empty; give a new one",
                path.display()
            ));
        }
    } else if path.exists() {
        return Err(anyhow!("{}: exists and is not a directory", path.display()));
    }
    let name = path
        .file_name()
        .ok_or_else(|| anyhow!("{}: not a directory name", path.display()))?
        .to_string_lossy();
    let tmp = path.with_file_name(format!(".{name}.{}.partial", std::process::id()));
    let result = render(&tmp).and_then(|value| {
        std::fs::rename(&tmp, path)
            .with_context(|| format!("cannot write {}", path.display()))
            .map(|()| value)
    });
    if result.is_err() {
        let _ = std::fs::remove_dir_all(&tmp);
    }
    result
}

/// The SHA-256 of a file, in hex (read a block at a time).
pub(crate) fn sha256(path: &Path) -> Result<String> {
    use sha2::Digest;
    let mut hasher = sha2::Sha256::new();
    let mut file = std::fs::File::open(path).with_context(|| format!("{}", path.display()))?;
    let mut buffer = vec![0u8; 1 << 16];
    loop {
        let n = std::io::Read::read(&mut file, &mut buffer)
            .with_context(|| format!("{}", path.display()))?;
        if n == 0 {
            break;
        }
        hasher.update(buffer.get(..n).unwrap_or_default());
    }
    Ok(hasher
        .finalize()
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect())
}

/// The SHA-256 of bytes, in hex.
pub(crate) fn sha256_bytes(bytes: &[u8]) -> String {
    use sha2::Digest;
    sha2::Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}
