//! DBC files as the commands load them: leniently, each diagnostic on stderr as
//! `file:line:column`, errors counted.

use std::path::Path;

use anyhow::{Context, Result};
use bywire_dbc::{Database, Mode};

/// Load a DBC file (strictly: the first problem is an error), its diagnostics on stderr.
pub fn load(path: &Path, strict: bool) -> Result<Database> {
    Ok(load_counting_errors(path, strict)?.0)
}

/// Load a DBC file, its diagnostics on stderr, with how many of them were errors (what the
/// lenient parser had to drop or guess).
pub fn load_counting_errors(path: &Path, strict: bool) -> Result<(Database, usize)> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    let mode = if strict { Mode::Strict } else { Mode::Lenient };
    let (db, diagnostics) = bywire_dbc::parse(&bytes, mode)
        .map_err(|e| anyhow::anyhow!("{}:{}", path.display(), e.0))?;
    for d in &diagnostics {
        eprintln!("{}:{d}", path.display());
    }
    let errors = diagnostics
        .iter()
        .filter(|d| d.severity == bywire_dbc::Severity::Error)
        .count();
    Ok((db, errors))
}
