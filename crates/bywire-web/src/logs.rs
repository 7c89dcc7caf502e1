//! Logs on the page: the files the server was given (any format bywire reads), each summed up
//! once (frames, time span, buses), its frames from any time (what the page's player shows and
//! steps through), a signal over any span decimated to the points a plot can draw (so a big
//! log plots at once), and a span exported to any log format.
//!
//! Only the files given to the server are read: a request names a log by its number, never by
//! a path.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use bywire_dbc::codec::Decoded;
use bywire_dbc::json::value_json;
use bywire_log::format::{Format, Records};
use bywire_log::LogRecord;
use serde_json::{json, Value as Json};

use crate::hub::{frame_json, Database};

/// Frames one request may ask for.
pub const MAX_FRAMES: usize = 5000;
/// Points one series may ask for.
pub const MAX_POINTS: usize = 20_000;

/// A signal's value at a time (ns).
type Sample = (u64, f64);

/// A log's summary, worked out by reading it once.
#[derive(Debug, Clone)]
pub struct Summary {
    /// Its format.
    pub format: Format,
    /// Its frames.
    pub frames: u64,
    /// The first and last frame's time (ns since the epoch).
    pub span: (u64, u64),
    /// Its buses (interfaces) and their frames.
    pub buses: BTreeMap<String, u64>,
    /// Records it could not read, passed over.
    pub unreadable: u64,
}

/// Where a reading of a log has got to: the next record and the reader after it, kept so a
/// player moving forward reads on instead of from the start. It lives on its log's reading
/// thread (a reader need not be able to move between threads).
struct Cursor {
    next: Option<LogRecord>,
    records: Records<'static>,
}

/// A request for frames, answered on `answer`.
struct FramesRequest {
    from: u64,
    count: usize,
    answer: std::sync::mpsc::Sender<Result<Json, String>>,
}

/// One log.
struct Entry {
    path: PathBuf,
    /// What the page calls it (its file name, or the name it was uploaded under).
    name: String,
    summary: Mutex<Option<Summary>>,
    /// Its reading thread, started at the first request for frames.
    reader: Mutex<Option<std::sync::mpsc::Sender<FramesRequest>>>,
}

/// The logs the server was given, with the database their frames are decoded with, and those
/// uploaded (kept in a temporary folder removed when the server ends).
pub struct Logs {
    entries: std::sync::RwLock<Vec<Arc<Entry>>>,
    database: Option<Arc<Database>>,
    uploads: Option<Mutex<Uploads>>,
}

/// Where uploaded logs go, and how much has gone there.
struct Uploads {
    folder: Option<tempfile::TempDir>,
    files: usize,
    bytes: u64,
}

/// The largest log one upload may be.
pub const MAX_UPLOAD: u64 = 2 << 30;
/// What all uploads together may fill.
pub const MAX_UPLOADS_BYTES: u64 = 8 << 30;
/// Uploads in all.
pub const MAX_UPLOADS: usize = 64;

fn entry(path: PathBuf, name: String) -> Arc<Entry> {
    Arc::new(Entry {
        path,
        name,
        summary: Mutex::new(None),
        reader: Mutex::new(None),
    })
}

fn reading(path: &std::path::Path, e: impl std::fmt::Display) -> String {
    format!("{}: {e}", path.display())
}

impl Logs {
    /// The files at `paths`, decoded with `database`; `uploads`: whether the page may add
    /// logs of its own.
    pub fn new(paths: Vec<PathBuf>, database: Option<Arc<Database>>, uploads: bool) -> Self {
        Logs {
            entries: std::sync::RwLock::new(
                paths
                    .into_iter()
                    .map(|path| {
                        let name = path.file_name().map_or_else(
                            || path.display().to_string(),
                            |n| n.to_string_lossy().into_owned(),
                        );
                        entry(path, name)
                    })
                    .collect(),
            ),
            database,
            uploads: uploads.then(|| {
                Mutex::new(Uploads {
                    folder: None,
                    files: 0,
                    bytes: 0,
                })
            }),
        }
    }

    fn entries(&self) -> std::sync::RwLockReadGuard<'_, Vec<Arc<Entry>>> {
        self.entries
            .read()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// Whether the page may upload logs.
    pub fn takes_uploads(&self) -> bool {
        self.uploads.is_some()
    }

    /// An uploaded log, `length` bytes read from `body`, under `name`: its number. Refused past
    /// [`MAX_UPLOAD`], [`MAX_UPLOADS_BYTES`] or [`MAX_UPLOADS`], or when uploads are off; a
    /// body cut short leaves nothing behind.
    pub fn upload(
        &self,
        name: &str,
        length: u64,
        body: &mut impl std::io::Read,
    ) -> Result<usize, String> {
        let uploads = self
            .uploads
            .as_ref()
            .ok_or("this server takes no uploads")?;
        let mut uploads = uploads
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if length > MAX_UPLOAD {
            return Err(format!(
                "{length} bytes: a log of at most {MAX_UPLOAD} bytes"
            ));
        }
        if uploads.files >= MAX_UPLOADS || uploads.bytes + length > MAX_UPLOADS_BYTES {
            return Err(format!(
                "the uploads are full ({} logs, {} bytes)",
                uploads.files, uploads.bytes
            ));
        }
        if uploads.folder.is_none() {
            uploads.folder = Some(
                tempfile::Builder::new()
                    .prefix("bywire-web-")
                    .tempdir()
                    .map_err(|e| e.to_string())?,
            );
        }
        let folder = uploads
            .folder
            .as_ref()
            .ok_or("no folder")?
            .path()
            .to_path_buf();
        // The name only as far as a file name can take it; the number keeps names apart.
        let safe: String = name
            .chars()
            .filter(|c| c.is_ascii_alphanumeric() || "._-".contains(*c))
            .take(64)
            .collect();
        let path = folder.join(format!(
            "{}-{}",
            uploads.files,
            safe.trim_start_matches('.')
        ));
        let mut file = std::fs::File::create(&path).map_err(|e| e.to_string())?;
        let copied = std::io::copy(&mut std::io::Read::take(body, length), &mut file)
            .map_err(|e| e.to_string())?;
        if copied != length {
            let _ = std::fs::remove_file(&path);
            return Err(format!("the upload ended after {copied} of {length} bytes"));
        }
        uploads.files += 1;
        uploads.bytes += length;
        let mut entries = self
            .entries
            .write()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        entries.push(entry(path, name.chars().take(128).collect()));
        Ok(entries.len() - 1)
    }

    /// The logs' database.
    pub fn database(&self) -> Option<&Database> {
        self.database.as_deref()
    }

    /// Whether there are none and none can be added.
    pub fn is_empty(&self) -> bool {
        self.entries().is_empty() && !self.takes_uploads()
    }

    fn entry(&self, log: usize) -> Result<Arc<Entry>, String> {
        let entries = self.entries();
        entries
            .get(log)
            .cloned()
            .ok_or_else(|| format!("no log {log} (there are {})", entries.len()))
    }

    /// The logs, by number: name and size; and whether the page may upload more.
    pub fn list(&self) -> Json {
        let logs: Vec<Json> = self
            .entries()
            .iter()
            .enumerate()
            .map(|(id, e)| {
                json!({
                    "id": id,
                    "name": e.name,
                    "bytes": std::fs::metadata(&e.path).map(|m| m.len()).ok(),
                })
            })
            .collect();
        json!({ "logs": logs, "upload": self.takes_uploads() })
    }

    fn open(entry: &Entry) -> Result<(Format, Records<'static>), String> {
        Format::open_file(&entry.path).map_err(|e| reading(&entry.path, e))
    }

    /// Log `log`'s summary (read once, then remembered).
    pub fn summary(&self, log: usize) -> Result<Summary, String> {
        let entry = self.entry(log)?;
        let mut kept = entry
            .summary
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some(summary) = kept.as_ref() {
            return Ok(summary.clone());
        }
        let (format, records) = Self::open(&entry)?;
        let mut summary = Summary {
            format,
            frames: 0,
            span: (u64::MAX, 0),
            buses: BTreeMap::new(),
            unreadable: 0,
        };
        for record in records {
            let Ok(record) = record else {
                summary.unreadable += 1;
                continue;
            };
            let at = record.timestamp.as_nanos();
            summary.frames += 1;
            summary.span = (summary.span.0.min(at), summary.span.1.max(at));
            // A log names few buses; a hostile one many: the count is bounded.
            if summary.buses.len() < 256 || summary.buses.contains_key(&record.interface) {
                *summary.buses.entry(record.interface).or_default() += 1;
            }
        }
        if summary.frames == 0 {
            summary.span = (0, 0);
        }
        *kept = Some(summary.clone());
        Ok(summary)
    }

    /// A summary as the page reads it.
    pub fn summary_json(&self, log: usize) -> Result<Json, String> {
        let s = self.summary(log)?;
        let format = Format::ALL
            .iter()
            .find(|(f, _)| *f == s.format)
            .map_or("?", |(_, n)| *n);
        Ok(json!({
            "log": log,
            "format": format,
            "frames": s.frames,
            "start": seconds(s.span.0),
            "end": seconds(s.span.1),
            // Exact (a float of seconds is not), as text: JavaScript's numbers are floats.
            "start_ns": s.span.0.to_string(),
            "end_ns": s.span.1.to_string(),
            "buses": s.buses,
            "unreadable": s.unreadable,
        }))
    }

    /// Up to `count` frames of log `log` from time `from` (ns) on, each with its decoded
    /// signals; and the time of the frame after them (`next_ns`, exact, `null` at the end).
    pub fn frames(&self, log: usize, from: u64, count: usize) -> Result<Json, String> {
        let entry = self.entry(log)?;
        let (answer, answered) = std::sync::mpsc::channel();
        let request = FramesRequest {
            from,
            count: count.clamp(1, MAX_FRAMES),
            answer,
        };
        {
            let mut reader = entry
                .reader
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner);
            let sender = match reader.as_ref() {
                Some(sender) => sender.clone(),
                None => {
                    let (sender, requests) = std::sync::mpsc::channel();
                    let (path, database) = (entry.path.clone(), self.database.clone());
                    std::thread::Builder::new()
                        .name(format!("web-log-{log}"))
                        .spawn(move || serve_frames(&path, database.as_deref(), &requests))
                        .map_err(|e| e.to_string())?;
                    *reader = Some(sender.clone());
                    sender
                }
            };
            sender
                .send(request)
                .map_err(|_| "the log's reader has stopped".to_string())?;
        }
        answered
            .recv()
            .map_err(|_| "the log's reader has stopped".to_string())?
    }

    /// Signal `signal` of message `message` on bus `bus` of log `log` between `from` and `to`
    /// (ns): every value when there are at most `points`, else each of `points / 2` equal
    /// spans of time kept as its lowest and highest value, in time order (what a line plot
    /// of all the values would show).
    #[allow(clippy::too_many_arguments)]
    pub fn series(
        &self,
        log: usize,
        bus: &str,
        message: &str,
        signal: &str,
        from: u64,
        to: u64,
        points: usize,
    ) -> Result<Json, String> {
        let entry = self.entry(log)?;
        let database = self.database.as_deref().ok_or("no database (--db)")?;
        let decoder = database.decoder();
        let (index, found) = (0..decoder.message_count())
            .filter_map(|i| Some((i, decoder.message_at(i)?.0)))
            .find(|(_, m)| m.display_name() == message)
            .ok_or_else(|| format!("no message {message} in the database"))?;
        let names = bywire_dbc::decoder::field_names(found);
        let position = names
            .iter()
            .position(|n| n == signal)
            .ok_or_else(|| format!("message {message} has no signal {signal}"))?;
        let points = points.clamp(2, MAX_POINTS);
        let (_, records) = Self::open(&entry)?;
        let mut scratch: Vec<Option<Decoded>> = Vec::new();
        let mut all: Vec<Sample> = Vec::new();
        let buckets = points / 2;
        // Each bucket: (lowest, highest), each with its time.
        let mut kept: Vec<Option<(Sample, Sample)>> = vec![None; buckets];
        let span = to.saturating_sub(from).max(1);
        let mut samples = 0u64;
        for record in records.flatten() {
            let at = record.timestamp.as_nanos();
            if at < from || at > to || record.interface != bus {
                continue;
            }
            let Some((i, _, Ok(()))) = decoder.decode_into(&record.frame, &mut scratch) else {
                continue;
            };
            if i != index {
                continue;
            }
            let Some(Some(value)) = scratch.get(position) else {
                continue;
            };
            let Some(y) = value_json(value.physical).as_f64() else {
                continue;
            };
            samples += 1;
            if all.len() <= points {
                all.push((at, y));
            }
            let slot = u128::try_from(buckets)
                .ok()
                .and_then(|b| usize::try_from(u128::from(at - from) * b / u128::from(span)).ok())
                .unwrap_or(0)
                .min(buckets.saturating_sub(1));
            if let Some(bucket) = kept.get_mut(slot) {
                *bucket = Some(match *bucket {
                    None => ((at, y), (at, y)),
                    Some((low, high)) => (
                        if y < low.1 { (at, y) } else { low },
                        if y > high.1 { (at, y) } else { high },
                    ),
                });
            }
        }
        let chosen: Vec<Sample> = if all.len() <= points {
            all
        } else {
            kept.into_iter()
                .flatten()
                .flat_map(|(low, high)| {
                    if low.0 <= high.0 {
                        [low, high]
                    } else {
                        [high, low]
                    }
                })
                .collect()
        };
        let x: Vec<f64> = chosen.iter().map(|(t, _)| seconds(*t)).collect();
        let y: Vec<f64> = chosen.iter().map(|(_, v)| *v).collect();
        let decimated = u64::try_from(points).is_ok_and(|p| samples > p);
        Ok(json!({ "x": x, "y": y, "samples": samples, "decimated": decimated }))
    }

    /// Log `log`'s frames between `from` and `to` (ns) written as `format` into a temporary
    /// file: the file and how many frames it holds.
    pub fn export(
        &self,
        log: usize,
        from: u64,
        to: u64,
        format: Format,
    ) -> Result<(tempfile::NamedTempFile, u64), String> {
        let entry = self.entry(log)?;
        let (_, records) = Self::open(&entry)?;
        let file = tempfile::NamedTempFile::new().map_err(|e| e.to_string())?;
        let output = file.reopen().map_err(|e| e.to_string())?;
        let mut writer = format
            .writer(std::io::BufWriter::new(output))
            .map_err(|e| e.to_string())?;
        let mut written = 0u64;
        for record in records.flatten() {
            let at = record.timestamp.as_nanos();
            if (from..=to).contains(&at) {
                writer.write(&record).map_err(|e| e.to_string())?;
                written += 1;
            }
        }
        writer.finish().map_err(|e| e.to_string())?;
        Ok((file, written))
    }
}

/// A log's reading thread: frames requests answered from one cursor, read on while requests
/// move forward, reopened when one goes back. Ends when the log is dropped.
fn serve_frames(
    path: &std::path::Path,
    database: Option<&Database>,
    requests: &std::sync::mpsc::Receiver<FramesRequest>,
) {
    let mut cursor: Option<Cursor> = None;
    let mut scratch: Vec<Option<Decoded>> = Vec::new();
    // Bounded by the requests (each bounded by its count and the log's length).
    while let Ok(request) = requests.recv() {
        let usable = cursor
            .as_ref()
            .and_then(|c| c.next.as_ref())
            .is_some_and(|next| next.timestamp.as_nanos() <= request.from);
        if !usable {
            cursor = match Format::open_file(path) {
                Ok((_, records)) => Some(Cursor {
                    next: None,
                    records,
                }),
                Err(e) => {
                    let _ = request.answer.send(Err(reading(path, e)));
                    continue;
                }
            };
        }
        let Some(c) = cursor.as_mut() else { continue };
        let mut frames = Vec::new();
        loop {
            let record = match c.next.take() {
                Some(record) => record,
                None => match c.records.next() {
                    Some(Ok(record)) => record,
                    Some(Err(_)) => continue,
                    None => break,
                },
            };
            if record.timestamp.as_nanos() < request.from {
                continue;
            }
            if frames.len() >= request.count {
                c.next = Some(record);
                break;
            }
            frames.push(frame_with_signals(database, &record, &mut scratch));
        }
        let next = c.next.as_ref().map(|r| r.timestamp.as_nanos().to_string());
        let _ = request
            .answer
            .send(Ok(json!({ "frames": frames, "next_ns": next })));
    }
}

/// A frame as the raw channel carries it, with its decoded `signals` when the database knows
/// it.
fn frame_with_signals(
    database: Option<&Database>,
    record: &LogRecord,
    scratch: &mut Vec<Option<Decoded>>,
) -> Json {
    let decoded =
        database.and_then(|d| Some((d, d.decoder().decode_into(&record.frame, scratch)?)));
    let name = decoded.as_ref().map(|(_, (_, m, _))| m.display_name());
    let mut frame = frame_json(&record.interface, record.timestamp, &record.frame, name);
    if let (Some((database, (index, message, Ok(())))), Json::Object(object)) =
        (decoded, &mut frame)
    {
        if let Some(signals) = database.object(index, message, scratch) {
            object.insert("signals".into(), Json::Object(signals));
        }
    }
    frame
}

/// Nanoseconds as seconds (what the page counts in).
#[allow(clippy::cast_precision_loss)]
fn seconds(nanos: u64) -> f64 {
    nanos as f64 / 1e9
}

/// A time in seconds (as the page gives it) in nanoseconds; `None` for one that is not.
pub fn seconds_to_nanos(text: &str) -> Option<u64> {
    let seconds: f64 = text
        .parse()
        .ok()
        .filter(|s: &f64| s.is_finite() && *s >= 0.0)?;
    // Seconds since 1970 fit in a float's mantissa to below a microsecond.
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
    Some((seconds * 1e9).min(u64::MAX as f64) as u64)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::indexing_slicing)]
    use super::*;

    const DBC: &str = "VERSION \"\"\n\nBU_: A\n\nBO_ 256 Ramp: 2 A\n SG_ Value : 0|16@1+ (1,0) [0|65535] \"\" A\n";

    /// 1,000 frames of a ramp that dips to zero at frame 500, on can0 (and noise on can1).
    fn log() -> (tempfile::TempDir, Logs) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("ramp.log");
        let mut text = String::new();
        for i in 0..1000u32 {
            let value = if i == 500 { 0 } else { i + 1 };
            let [a, b, ..] = value.to_le_bytes();
            text.push_str(&format!("(1700000000.{i:06}) can0 100#{a:02X}{b:02X}\n"));
            text.push_str(&format!("(1700000000.{i:06}) can1 100#FFFF\n"));
        }
        std::fs::write(&path, text).unwrap();
        let (db, _) = bywire_dbc::parse_str(DBC, bywire_dbc::Mode::Strict).unwrap();
        let database = Arc::new(Database::new(bywire_dbc::decoder::Decoder::new(db)));
        (dir, Logs::new(vec![path], Some(database), false))
    }

    #[test]
    fn a_series_keeps_every_extreme_when_decimated() {
        let (_dir, logs) = log();
        let start = 1_700_000_000_000_000_000;
        let all = logs
            .series(0, "can0", "Ramp", "Value", start, start + 1_000_000, 5000)
            .unwrap();
        assert_eq!(all["samples"], 1000);
        assert_eq!(all["decimated"], false);
        assert_eq!(all["y"].as_array().unwrap().len(), 1000);
        let few = logs
            .series(0, "can0", "Ramp", "Value", start, start + 1_000_000, 100)
            .unwrap();
        let y: Vec<f64> = few["y"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        assert!(y.len() <= 100, "{}", y.len());
        assert_eq!(few["decimated"], true);
        // The dip and the ends survive decimation; nothing of can1 (0xFFFF) shows.
        assert!(
            y.contains(&0.0) && y.contains(&1.0) && y.contains(&1000.0),
            "{y:?}"
        );
        assert!(y.iter().all(|v| *v <= 1000.0));
        let x = few["x"].as_array().unwrap();
        assert!(x.windows(2).all(|w| w[0].as_f64() <= w[1].as_f64()));
        assert!(logs
            .series(0, "can0", "Ramp", "Nothing", start, start + 1, 10)
            .is_err());
        assert!(logs
            .series(1, "can0", "Ramp", "Value", start, start + 1, 10)
            .is_err());
    }

    #[test]
    fn frames_read_on_forward_and_again_from_an_earlier_time() {
        let (_dir, logs) = log();
        let summary = logs.summary(0).unwrap();
        assert_eq!(summary.frames, 2000);
        assert_eq!(summary.buses.get("can1"), Some(&1000));
        let first = logs.frames(0, summary.span.0, 3).unwrap();
        assert_eq!(first["frames"].as_array().unwrap().len(), 3);
        assert_eq!(first["frames"][0]["signals"]["Value"], 1);
        let next: u64 = first["next_ns"].as_str().unwrap().parse().unwrap();
        let second = logs.frames(0, next, 2).unwrap();
        assert_eq!(second["frames"][0]["bus"], "can1");
        assert_eq!(second["frames"][1]["signals"]["Value"], 3);
        // Back to the start: the same first frame.
        let again = logs.frames(0, summary.span.0, 1).unwrap();
        assert_eq!(again["frames"][0], first["frames"][0]);
        let end = logs.frames(0, summary.span.1 + 1, 10).unwrap();
        assert!(end["frames"].as_array().unwrap().is_empty() && end["next_ns"].is_null());
    }
}
