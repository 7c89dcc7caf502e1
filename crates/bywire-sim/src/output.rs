//! A run's files in its folder: each bus's log (`bus1.log` … in candump `-L` form), the
//! ground truth (`truth.csv`, [`crate::truth`]) and the report (`metrics.json`) — the same
//! files whichever front end ran it (`bywire sim`, a sweep, Python).

use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};

use bywire_core::Timestamp;
use core::time::Duration;

use crate::report::RunReport;
use crate::tug::Tug;

/// A simulated time on the logs' clock, which reads `start` at the run's start.
pub(crate) fn on_logs_clock(start: Timestamp, simulated: Timestamp) -> Timestamp {
    start.saturating_add(Duration::from_nanos(simulated.as_nanos()))
}

/// Write `tug`'s logs, truth and `report` into `dir` (created if needed), the logs' and the
/// truth's times from the report's start time; the paths written.
/// `metrics.json` comes last, written whole or not at all: a reader that finds it finds the
/// rest complete.
pub fn write_run(tug: &Tug, report: &RunReport, dir: &Path) -> io::Result<Vec<PathBuf>> {
    let named =
        |path: &Path, e: io::Error| io::Error::new(e.kind(), format!("{}: {e}", path.display()));
    std::fs::create_dir_all(dir).map_err(|e| named(dir, e))?;
    let mut written = Vec::new();
    let start = Timestamp::from_nanos(report.start_time_ns);
    for (name, log) in tug.bus_logs() {
        let path = dir.join(format!("{name}.log"));
        let file = File::create(&path).map_err(|e| named(&path, e))?;
        let mut writer = bywire_log::Writer::new(BufWriter::new(file));
        for (timestamp, frame) in log {
            writer
                .write(on_logs_clock(start, *timestamp), name, frame)
                .map_err(|e| named(&path, e))?;
        }
        writer.flush().map_err(|e| named(&path, e))?;
        written.push(path);
    }
    let path = dir.join("truth.csv");
    let mut truth = BufWriter::new(File::create(&path).map_err(|e| named(&path, e))?);
    crate::truth::write_csv(&tug.truth, start, &mut truth)
        .and_then(|()| truth.flush())
        .map_err(|e| named(&path, e))?;
    written.push(path);
    let path = dir.join("metrics.json");
    let json = serde_json::to_string_pretty(report).map_err(io::Error::other)?;
    let tmp = dir.join(".metrics.json.tmp");
    std::fs::write(&tmp, json + "\n")
        .and_then(|()| std::fs::rename(&tmp, &path))
        .map_err(|e| named(&path, e))?;
    written.push(path);
    Ok(written)
}
