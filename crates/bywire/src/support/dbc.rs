//! Databases as the commands load them: any format bywire reads (by `--db-format`, else the
//! extension, else the content), leniently, each diagnostic on stderr as
//! `file:line:column`, errors counted.

use std::path::Path;
use std::sync::OnceLock;

use anyhow::{Context, Result};
use bywire_dbc::{Database, Format, Mode};

static FORCED: OnceLock<Option<Format>> = OnceLock::new();

/// Read every database as `format` from now on (`--db-format`).
pub fn force_format(format: Option<Format>) {
    let _ = FORCED.set(format);
}

static BUS: OnceLock<Option<String>> = OnceLock::new();

/// Read only this bus of every database from now on (`--db-bus`).
pub fn select_bus(bus: Option<String>) {
    let _ = BUS.set(bus);
}

/// `--db-format`'s value.
pub fn parse_format(name: &str) -> Result<Format, String> {
    Format::from_name(name).ok_or_else(|| {
        let names: Vec<&str> = Format::ALL.iter().map(|f| f.name()).collect();
        format!("{name} is not a database format ({})", names.join(", "))
    })
}

/// The format `path` is read as.
pub fn format_of(path: &Path, bytes: &[u8]) -> Format {
    Format::of_file(FORCED.get().copied().flatten(), path, bytes)
}

/// Load a database (strictly: the first problem is an error), its diagnostics on stderr.
pub fn load(path: &Path, strict: bool) -> Result<Database> {
    Ok(load_counting_errors(path, strict)?.0)
}

/// Load a database, its diagnostics on stderr, with how many of them were errors (what the
/// lenient reader had to drop or guess).
pub fn load_counting_errors(path: &Path, strict: bool) -> Result<(Database, usize)> {
    let (db, errors, _) = load_with_format(path, strict)?;
    Ok((db, errors))
}

/// [`load_counting_errors`] with the format the file was read as.
pub fn load_with_format(path: &Path, strict: bool) -> Result<(Database, usize, Format)> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    let mode = if strict { Mode::Strict } else { Mode::Lenient };
    let format = format_of(path, &bytes);
    let bus = BUS.get().and_then(Option::as_deref);
    let (db, diagnostics) = bywire_dbc::format::load_bus(&bytes, format, mode, bus)
        .map_err(|e| anyhow::anyhow!("{}:{}", path.display(), e.0))?;
    for d in &diagnostics {
        eprintln!("{}:{d}", path.display());
    }
    let errors = diagnostics
        .iter()
        .filter(|d| d.severity == bywire_dbc::Severity::Error)
        .count();
    Ok((db, errors, format))
}
