//! Logs as the commands read them (candump or ASC, sniffed from the content): files or
//! standard input, every line checked, and what cannot be read reported on standard error with
//! its file and line.

use std::fs::File;
use std::io::{self, BufRead, BufReader, Write};
use std::path::{Path, PathBuf};

use anyhow::{anyhow, Context, Result};
use bywire_log::format::Format;
use bywire_log::{LogError, LogErrorKind, LogRecord, Reader};

/// A log to read: its bytes, and the file itself when it is one (Parquet is read by seeking).
pub struct LogInput {
    bytes: Box<dyn BufRead>,
    file: Option<File>,
}

impl LogInput {
    /// A handle on the file that shares its read position (for a progress bar).
    pub fn position_probe(&self) -> Option<File> {
        self.file.as_ref().and_then(|f| f.try_clone().ok())
    }
}

/// The files to read, each with the name its messages use (standard input when none).
pub fn inputs(files: &[PathBuf]) -> Result<Vec<(String, LogInput)>> {
    if files.is_empty() {
        return Ok(vec![input(None)?]);
    }
    files.iter().map(|p| input(Some(p))).collect()
}

/// One file (or standard input) with its name.
pub fn input(path: Option<&Path>) -> Result<(String, LogInput)> {
    match path {
        None => Ok((
            "standard input".into(),
            LogInput {
                bytes: Box::new(BufReader::new(io::stdin())),
                file: None,
            },
        )),
        Some(p) => {
            let file = File::open(p).with_context(|| format!("cannot open {}", p.display()))?;
            let reader = file
                .try_clone()
                .with_context(|| format!("cannot open {}", p.display()))?;
            Ok((
                p.display().to_string(),
                LogInput {
                    bytes: Box::new(BufReader::new(reader)),
                    file: Some(file),
                },
            ))
        }
    }
}

/// Which bad lines are skipped (with a warning) rather than ending the read.
#[derive(Clone, Copy, PartialEq, Eq)]
pub enum Skip {
    /// Lines that cannot be text: too long, not UTF-8. A malformed log line is an error.
    Unreadable,
    /// As `Unreadable`, and in candump logs lines that are not log lines at all are passed
    /// over without a word, as canplayer does.
    NonLogLines,
    /// Every bad line, and lines that are not log lines at all (a plot of what can be read).
    AnyBadLine,
}

/// The records of `input` (called `name` in messages); skipped lines are reported.
pub fn records<'a>(
    name: &'a str,
    input: LogInput,
    skip: Skip,
) -> impl Iterator<Item = Result<LogRecord>> + 'a {
    let LogInput { mut bytes, file } = input;
    // An input that cannot even be peeked at fails on its first read, with its name.
    let format = Format::sniff_input(&mut bytes).unwrap_or(Format::Candump);
    let reader = match (format, skip, file) {
        (Format::Candump, Skip::AnyBadLine | Skip::NonLogLines, _) => {
            Box::new(Reader::new(bytes).log_lines_only())
        }
        (Format::Parquet, _, Some(file)) => format.file_reader(file),
        (format, _, _) => format.reader(bytes),
    };
    reader.filter_map(move |record| match record {
        Err(e @ LogError::Syntax { .. }) if skip == Skip::AnyBadLine => {
            let _ = writeln!(io::stderr(), "{name}: {e} (skipped)");
            None
        }
        Err(
            e @ LogError::Syntax {
                kind: LogErrorKind::TooLong(_) | LogErrorKind::NotUtf8,
                ..
            },
        ) => {
            let _ = writeln!(io::stderr(), "{name}: {e} (skipped)");
            None
        }
        other => Some(other.map_err(|e| anyhow!("{name}: {e}"))),
    })
}
