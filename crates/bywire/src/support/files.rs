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
