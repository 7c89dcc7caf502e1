//! A field recorder: frames from several buses into log files that survive the recorder's end.
//!
//! - **Layout:** one file per bus, or one merged file for all of them.
//! - **Rotation:** a file is finished and a new one begun when it reaches a size or spans a
//!   time; a finished file is complete (its format's closing structures written) and synced.
//! - **Checkpoints:** every so often each open file is made complete as it stands
//!   ([`RecordWriter::checkpoint`]) and synced, so a kill or a power loss loses at most the
//!   time since the last one (Parquet excepted: see [`Format::survives_a_cut`]).
//! - **Trigger window:** instead of recording everything, frames are held for the last
//!   `before` of bus time and written only when a trigger comes, with everything up to `after`
//!   past the last trigger; each capture is a file (or a file per bus) of its own.
//! - **Metadata:** beside each file, `FILE.json` (written atomically) says what it holds: the
//!   caller's facts (vehicle, profile, DBC hash, host, bitrates), the format, the buses with
//!   their frame and drop counts, the first and last frame, the triggers, and `"status"`:
//!   `recording` while the file is open (what a cut file's metadata still says) and `complete`
//!   once it is finished.
//!
//! Time is passed in: a record's own timestamp for rotation spans and the trigger window, the
//! caller's clock ([`Recorder::tick`]) for checkpoints and for windows and spans that end on a
//! quiet bus. Memory is bounded: the held frames by a count as well as by time.

use std::collections::{BTreeMap, VecDeque};
use std::fs::File;
use std::io::{self, BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use crate::calendar::utc_text;
use crate::candump::LogRecord;
use crate::format::{Format, ParquetCompression, RecordWriter};

/// The most triggers a file's metadata lists (more are counted).
pub const MAX_TRIGGERS_LISTED: usize = 10_000;

/// Where the buses' frames go.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Layout {
    /// A file per bus.
    PerBus,
    /// One file for all buses.
    Merged,
}

/// When a file is finished and the next begun (either limit; none: one file).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Rotation {
    /// Bytes a file may reach.
    pub max_bytes: Option<u64>,
    /// Nanoseconds a file may span, from its first frame.
    pub max_span_ns: Option<u64>,
}

/// The trigger window: what is kept around a trigger.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Window {
    /// Nanoseconds of frames kept before a trigger.
    pub before_ns: u64,
    /// Nanoseconds recorded after the last trigger.
    pub after_ns: u64,
    /// The most frames held before a trigger (the oldest go first; they are counted).
    pub max_held: usize,
}

/// How a recorder records.
#[derive(Debug, Clone)]
pub struct Config {
    /// The folder the files go to (it must exist).
    pub dir: PathBuf,
    /// The start of every file's name (`NAME-0001.blf`, `NAME-0001-can0.blf`).
    pub name: String,
    /// The files' format.
    pub format: Format,
    /// What Parquet files' pages are compressed with (other formats ignore it).
    pub compression: ParquetCompression,
    /// A file per bus or one for all.
    pub layout: Layout,
    /// When files are rotated.
    pub rotation: Rotation,
    /// Nanoseconds between checkpoints (by the caller's clock).
    pub checkpoint_ns: u64,
    /// Record only around triggers.
    pub window: Option<Window>,
    /// The caller's facts, written into every file's metadata.
    pub metadata: serde_json::Map<String, serde_json::Value>,
}

/// A file finished.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Finished {
    /// Its path.
    pub path: PathBuf,
    /// Frames in it.
    pub frames: u64,
    /// Its size.
    pub bytes: u64,
}

/// How far the recording has come.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Progress {
    /// Frames written to files.
    pub frames_written: u64,
    /// Bytes in the files (finished and open).
    pub bytes_written: u64,
    /// Files begun.
    pub files: u64,
    /// Frames held for a trigger now.
    pub held: usize,
    /// Held frames let go for room (not for age) before any trigger came.
    pub held_overflow: u64,
    /// Whether a trigger's capture is being written.
    pub capturing: bool,
}

/// The end of a [`Write`] + [`Seek`] file, kept where the recorder can read it while the
/// format's writer owns the file.
struct Counted {
    out: BufWriter<File>,
    at: u64,
    end: Arc<AtomicU64>,
}

impl Write for Counted {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let n = self.out.write(buf)?;
        self.at += n as u64;
        self.end.fetch_max(self.at, Ordering::Relaxed);
        Ok(n)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.out.flush()
    }
}

impl Seek for Counted {
    fn seek(&mut self, to: SeekFrom) -> io::Result<u64> {
        self.at = self.out.seek(to)?;
        Ok(self.at)
    }
}

/// What a file's metadata says of it.
struct Facts {
    path: PathBuf,
    sequence: u32,
    bytes: u64,
    first_ns: Option<u64>,
    last_ns: u64,
    frames: BTreeMap<String, u64>,
    triggers: Vec<(u64, String)>,
    triggers_not_listed: u64,
}

impl Facts {
    fn frame_count(&self) -> u64 {
        self.frames.values().sum()
    }

    fn note_trigger(&mut self, at: u64, reason: &str) {
        // The same reason again within a file is the same event going on.
        if self.triggers.last().is_some_and(|(_, last)| last == reason) {
            return;
        }
        if self.triggers.len() < MAX_TRIGGERS_LISTED {
            self.triggers.push((at, reason.to_string()));
        } else {
            self.triggers_not_listed += 1;
        }
    }
}

/// One open file.
struct OpenFile {
    writer: RecordWriter<Counted>,
    /// The same file, to sync it.
    sync: File,
    end: Arc<AtomicU64>,
    facts: Facts,
    /// Written to since its last checkpoint.
    dirty: bool,
}

impl OpenFile {
    fn bytes(&self) -> u64 {
        self.end.load(Ordering::Relaxed)
    }
}

/// A capture under way (trigger window mode).
#[derive(Debug, Clone, Copy)]
struct Capture {
    until_ns: u64,
}

/// The recorder (see the [module](self)).
pub struct Recorder {
    config: Config,
    /// Open files by key: the bus's name, or `""` when merged.
    open: BTreeMap<String, OpenFile>,
    next_sequence: u32,
    held: VecDeque<LogRecord>,
    capture: Option<Capture>,
    /// Triggers of a capture whose files are not open yet.
    pending_triggers: Vec<(u64, String)>,
    last_checkpoint_ns: Option<u64>,
    /// Each bus's drops as the caller last gave them (the kernel's or the endpoint's count).
    drops: BTreeMap<String, u64>,
    progress: Progress,
    finished_bytes: u64,
    finished: Vec<Finished>,
}

/// A name safe in a file name: letters, digits, `-`, `_` and `.`; anything else is `_`.
fn file_safe(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.') {
                c
            } else {
                '_'
            }
        })
        .collect()
}

fn extension(format: Format) -> &'static str {
    match format {
        Format::Candump => "log",
        Format::Asc => "asc",
        Format::Trc => "trc",
        Format::Pcapng => "pcapng",
        Format::Blf => "blf",
        Format::Mcap => "mcap",
        Format::Parquet => "parquet",
        Format::Mf4 => "mf4",
    }
}

/// Sync a folder, so the names of files just created or renamed in it survive a power loss.
fn sync_dir(dir: &Path) -> io::Result<()> {
    File::open(dir)?.sync_all()
}

impl Recorder {
    /// A recorder writing into `config.dir` (which must be a folder it can write in: checked
    /// now, so a wrong path fails before any frame is taken).
    pub fn new(config: Config) -> io::Result<Recorder> {
        let probe = config
            .dir
            .join(format!(".{}.probe", file_safe(&config.name)));
        File::create(&probe).map_err(|e| {
            io::Error::new(
                e.kind(),
                format!("cannot write in {}: {e}", config.dir.display()),
            )
        })?;
        std::fs::remove_file(&probe)?;
        Ok(Recorder {
            config,
            open: BTreeMap::new(),
            next_sequence: 1,
            held: VecDeque::new(),
            capture: None,
            pending_triggers: Vec::new(),
            last_checkpoint_ns: None,
            drops: BTreeMap::new(),
            progress: Progress::default(),
            finished_bytes: 0,
            finished: Vec::new(),
        })
    }

    /// How far the recording has come.
    pub fn progress(&self) -> Progress {
        Progress {
            bytes_written: self.finished_bytes
                + self.open.values().map(OpenFile::bytes).sum::<u64>(),
            held: self.held.len(),
            capturing: self.capture.is_some(),
            ..self.progress.clone()
        }
    }

    /// The files finished so far.
    pub fn finished(&self) -> &[Finished] {
        &self.finished
    }

    /// Note `bus`'s drops so far (a running total), for the metadata.
    pub fn set_dropped(&mut self, bus: &str, total: u64) {
        self.drops.insert(bus.to_string(), total);
    }

    /// Take one frame.
    pub fn record(&mut self, record: LogRecord) -> io::Result<()> {
        let at = record.timestamp.as_nanos();
        let Some(window) = self.config.window else {
            return self.write(&record);
        };
        if let Some(capture) = self.capture {
            if at <= capture.until_ns {
                return self.write(&record);
            }
            self.end_capture()?;
        }
        self.held.push_back(record);
        let oldest = at.saturating_sub(window.before_ns);
        while self
            .held
            .front()
            .is_some_and(|r| r.timestamp.as_nanos() < oldest)
        {
            self.held.pop_front();
        }
        while self.held.len() > window.max_held {
            self.held.pop_front();
            self.progress.held_overflow += 1;
        }
        Ok(())
    }

    /// A trigger at `at` (bus time) for `reason`. With a window it starts a capture (the held
    /// frames first) or extends the one under way; without, it is noted in the open files'
    /// metadata.
    pub fn trigger(&mut self, at: u64, reason: &str) -> io::Result<()> {
        if let Some(window) = self.config.window {
            let until_ns = at.saturating_add(window.after_ns);
            match &mut self.capture {
                Some(capture) => capture.until_ns = capture.until_ns.max(until_ns),
                None => {
                    self.capture = Some(Capture { until_ns });
                    let oldest = at.saturating_sub(window.before_ns);
                    while let Some(record) = self.held.pop_front() {
                        if record.timestamp.as_nanos() >= oldest {
                            self.write(&record)?;
                        }
                    }
                }
            }
        }
        if self.open.is_empty() && self.config.window.is_some() {
            // A capture with nothing held: its files open with its first frame.
            if self.pending_triggers.len() < MAX_TRIGGERS_LISTED {
                self.pending_triggers.push((at, reason.to_string()));
            }
        }
        for file in self.open.values_mut() {
            file.facts.note_trigger(at, reason);
        }
        Ok(())
    }

    /// Keep a capture under way going to `at` + the window's after-time, without noting a new
    /// trigger (a condition that goes on holding); nothing without a capture.
    pub fn extend(&mut self, at: u64) {
        if let (Some(window), Some(capture)) = (self.config.window, &mut self.capture) {
            capture.until_ns = capture.until_ns.max(at.saturating_add(window.after_ns));
        }
    }

    /// Let time pass (`now`, the caller's clock in nanoseconds since the Unix epoch, the base
    /// of the frames' timestamps): checkpoints fall due, a capture whose window has passed
    /// ends, a file past its span is rotated even on a quiet bus.
    pub fn tick(&mut self, now: u64) -> io::Result<()> {
        if let Some(capture) = self.capture {
            if now > capture.until_ns {
                self.end_capture()?;
            }
        }
        if let Some(span) = self.config.rotation.max_span_ns {
            let due: Vec<String> = self
                .open
                .iter()
                .filter(|(_, f)| {
                    f.facts
                        .first_ns
                        .is_some_and(|first| now.saturating_sub(first) >= span)
                })
                .map(|(key, _)| key.clone())
                .collect();
            for key in due {
                self.close(&key)?;
            }
        }
        let due = self
            .last_checkpoint_ns
            .is_none_or(|last| now.saturating_sub(last) >= self.config.checkpoint_ns);
        if due {
            self.last_checkpoint_ns = Some(now);
            self.checkpoint()?;
        }
        Ok(())
    }

    /// Make every open file complete as it stands and sync it (and its metadata).
    pub fn checkpoint(&mut self) -> io::Result<()> {
        let keys: Vec<String> = self
            .open
            .iter()
            .filter(|(_, f)| f.dirty)
            .map(|(k, _)| k.clone())
            .collect();
        for key in keys {
            let Some(file) = self.open.get_mut(&key) else {
                continue;
            };
            file.writer.checkpoint()?;
            file.sync.sync_data()?;
            file.dirty = false;
            file.facts.bytes = file.bytes();
            write_metadata(&self.config, &self.drops, &file.facts, "recording")?;
        }
        Ok(())
    }

    /// Finish every open file: the files written, in the order they were finished.
    pub fn finish(mut self) -> io::Result<Vec<Finished>> {
        let keys: Vec<String> = self.open.keys().cloned().collect();
        for key in keys {
            self.close(&key)?;
        }
        Ok(self.finished)
    }

    fn end_capture(&mut self) -> io::Result<()> {
        self.capture = None;
        let keys: Vec<String> = self.open.keys().cloned().collect();
        for key in keys {
            self.close(&key)?;
        }
        Ok(())
    }

    fn write(&mut self, record: &LogRecord) -> io::Result<()> {
        let key = match self.config.layout {
            Layout::PerBus => record.interface.as_str(),
            Layout::Merged => "",
        };
        if !self.open.contains_key(key) {
            let file = self.create(key)?;
            self.open.insert(key.to_string(), file);
        }
        let Some(file) = self.open.get_mut(key) else {
            return Ok(());
        };
        let at = record.timestamp.as_nanos();
        file.writer.write(record)?;
        let facts = &mut file.facts;
        let first = *facts.first_ns.get_or_insert(at);
        facts.last_ns = facts.last_ns.max(at);
        *facts.frames.entry(record.interface.clone()).or_default() += 1;
        file.dirty = true;
        self.progress.frames_written += 1;
        let rotation = self.config.rotation;
        let full = rotation.max_bytes.is_some_and(|max| file.bytes() >= max)
            || rotation
                .max_span_ns
                .is_some_and(|span| at.saturating_sub(first) >= span);
        if full {
            let key = key.to_string();
            self.close(&key)?;
        }
        Ok(())
    }

    fn create(&mut self, key: &str) -> io::Result<OpenFile> {
        let sequence = self.next_sequence;
        self.next_sequence = self.next_sequence.saturating_add(1);
        let mut name = format!("{}-{sequence:04}", self.config.name);
        if !key.is_empty() {
            name.push('-');
            name.push_str(&file_safe(key));
        }
        name.push('.');
        name.push_str(extension(self.config.format));
        // A log appears under its name only complete with its header and with its metadata
        // beside it: it is begun under a hidden partial name and renamed into place after the
        // metadata is written. A kill at any moment leaves no log without its `FILE.json` (at
        // worst a hidden `.NAME.part`, or metadata whose log was never begun).
        let path = self.config.dir.join(&name);
        let partial = self.config.dir.join(format!(".{name}.part"));
        let cannot = |e: io::Error| {
            io::Error::new(e.kind(), format!("cannot create {}: {e}", path.display()))
        };
        // A partial file is left only by a recorder stopped while it began that file.
        for taken in [path.clone(), sidecar(&path), partial.clone()] {
            if taken.try_exists().map_err(cannot)? {
                let exists = format!("{} exists", taken.display());
                return Err(cannot(io::Error::new(io::ErrorKind::AlreadyExists, exists)));
            }
        }
        let file = File::options()
            .write(true)
            .create_new(true)
            .open(&partial)
            .map_err(cannot)?;
        let begun = self.begin(file, path.clone(), sequence).and_then(|open| {
            std::fs::rename(&partial, &path)?;
            sync_dir(&self.config.dir)?;
            Ok(open)
        });
        if begun.is_err() {
            // Nothing half-made is left behind (both names were free when the file was begun).
            let _ = std::fs::remove_file(&partial);
            if !path.exists() {
                let _ = std::fs::remove_file(sidecar(&path));
            }
        }
        begun
    }

    /// A file begun as `file` (to be known as `path`) made a complete, empty log, synced, its
    /// metadata written.
    fn begin(&mut self, file: File, path: PathBuf, sequence: u32) -> io::Result<OpenFile> {
        let sync = file.try_clone()?;
        let end = Arc::new(AtomicU64::new(0));
        let counted = Counted {
            out: BufWriter::with_capacity(256 * 1024, file),
            at: 0,
            end: Arc::clone(&end),
        };
        let mut writer = self
            .config
            .format
            .writer_with(counted, self.config.compression)?;
        // On disk complete from the start (a header, MF4's empty groups): a kill before the
        // first checkpoint leaves an empty log, not a broken one.
        writer.checkpoint()?;
        sync.sync_data()?;
        let file = OpenFile {
            writer,
            sync,
            end,
            facts: Facts {
                path,
                sequence,
                bytes: 0,
                first_ns: None,
                last_ns: 0,
                frames: BTreeMap::new(),
                triggers: std::mem::take(&mut self.pending_triggers),
                triggers_not_listed: 0,
            },
            dirty: true,
        };
        write_metadata(&self.config, &self.drops, &file.facts, "recording")?;
        self.progress.files += 1;
        Ok(file)
    }

    /// Finish the open file under `key`: complete, synced, its metadata final.
    fn close(&mut self, key: &str) -> io::Result<()> {
        let Some(file) = self.open.remove(key) else {
            return Ok(());
        };
        let mut counted = file.writer.finish()?;
        counted.flush()?;
        file.sync.sync_all()?;
        let mut facts = file.facts;
        facts.bytes = file.end.load(Ordering::Relaxed);
        write_metadata(&self.config, &self.drops, &facts, "complete")?;
        self.finished_bytes += facts.bytes;
        self.finished.push(Finished {
            frames: facts.frame_count(),
            bytes: facts.bytes,
            path: facts.path,
        });
        Ok(())
    }
}

/// Where a file's metadata is kept: `FILE.json` beside it.
fn sidecar(path: &Path) -> PathBuf {
    let mut name = path.as_os_str().to_owned();
    name.push(".json");
    PathBuf::from(name)
}

/// `FILE.json` beside a file, written atomically (a temporary file renamed into place).
fn write_metadata(
    config: &Config,
    drops: &BTreeMap<String, u64>,
    facts: &Facts,
    status: &str,
) -> io::Result<()> {
    use serde_json::json;
    let buses: serde_json::Map<String, serde_json::Value> = facts
        .frames
        .iter()
        .map(|(bus, frames)| {
            let entry = match drops.get(bus) {
                Some(dropped) => json!({ "frames": frames, "dropped": dropped }),
                None => json!({ "frames": frames }),
            };
            (bus.clone(), entry)
        })
        .collect();
    let name = facts
        .path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let last = facts.first_ns.map(|_| facts.last_ns);
    let triggers: Vec<serde_json::Value> = facts
        .triggers
        .iter()
        .map(|(at, reason)| json!({ "at": utc_text(*at), "at_ns": at, "reason": reason }))
        .collect();
    let own = json!({
        "file": name,
        "status": status,
        "format": extension(config.format),
        "sequence": facts.sequence,
        "bytes": facts.bytes,
        "frames": facts.frame_count(),
        "buses": buses,
        "first_frame": facts.first_ns.map(utc_text),
        "last_frame": last.map(utc_text),
        "first_frame_ns": facts.first_ns,
        "last_frame_ns": last,
        "triggers": triggers,
        "triggers_not_listed": facts.triggers_not_listed,
        "checkpoint_interval_s": config.checkpoint_ns as f64 / 1e9,
        "survives_a_cut": config.format.survives_a_cut(),
    });
    let mut meta = config.metadata.clone();
    if let serde_json::Value::Object(own) = own {
        meta.extend(own);
    }
    let text =
        serde_json::to_string_pretty(&serde_json::Value::Object(meta)).map_err(io::Error::other)?;
    let target = sidecar(&facts.path).into_os_string();
    let mut temporary = target.clone();
    temporary.push(".tmp");
    {
        let mut out = File::create(&temporary)?;
        out.write_all(text.as_bytes())?;
        out.write_all(b"\n")?;
        out.sync_data()?;
    }
    std::fs::rename(&temporary, &target)
}

#[cfg(test)]
mod tests {
    use super::*;
    use bywire_core::frame::ClassicFrame;
    use bywire_core::{Frame, Id, Timestamp};

    const START: u64 = 1_700_000_000_000_000_000;
    const MS: u64 = 1_000_000;

    /// An empty folder for one test, removed with it.
    fn folder(test: &str) -> tempfile::TempDir {
        tempfile::Builder::new()
            .prefix(&format!("bywire-rec-{test}-"))
            .tempdir()
            .unwrap()
    }

    fn config(dir: &Path, format: Format, layout: Layout) -> Config {
        let mut metadata = serde_json::Map::new();
        metadata.insert("vehicle".into(), "tug-7".into());
        Config {
            dir: dir.to_path_buf(),
            name: "run".into(),
            format,
            compression: ParquetCompression::default(),
            layout,
            rotation: Rotation::default(),
            checkpoint_ns: 1_000 * MS,
            window: None,
            metadata,
        }
    }

    /// Frame `i` on bus `can{i % buses}` at `i` ms.
    fn record(i: u64, buses: u64) -> LogRecord {
        LogRecord {
            timestamp: Timestamp::from_nanos(START + i * MS),
            interface: format!("can{}", i % buses),
            frame: Frame::Classic(
                ClassicFrame::new(Id::standard(0x100).unwrap(), &i.to_le_bytes()).unwrap(),
            ),
            direction: Some('R'),
        }
    }

    fn numbers(path: &Path) -> Vec<u64> {
        let (_, records) = Format::open_file(path).unwrap();
        records
            .map_while(Result::ok)
            .map(|r| u64::from_le_bytes(r.frame.data().try_into().unwrap()))
            .collect()
    }

    fn metadata(path: &Path) -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(sidecar(path)).unwrap()).unwrap()
    }

    /// The names in `dir`.
    fn names(dir: &Path) -> Vec<std::ffi::OsString> {
        std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect()
    }

    #[test]
    fn rotated_files_hold_every_frame_once_in_order_with_their_metadata() {
        let scratch = folder("rotate");
        let dir = scratch.path();
        let mut config = config(dir, Format::Blf, Layout::Merged);
        config.rotation.max_bytes = Some(64 * 1024);
        let mut recorder = Recorder::new(config).unwrap();
        for i in 0..60_000 {
            recorder.record(record(i, 2)).unwrap();
        }
        let files = recorder.finish().unwrap();
        assert!(files.len() > 3, "{files:?}");
        let mut all = Vec::new();
        for file in &files {
            let read = numbers(&file.path);
            assert_eq!(read.len() as u64, file.frames);
            let meta = metadata(&file.path);
            assert_eq!(meta["status"], "complete");
            assert_eq!(meta["vehicle"], "tug-7");
            assert_eq!(meta["frames"], file.frames);
            assert_eq!(meta["bytes"], std::fs::metadata(&file.path).unwrap().len());
            let per_bus: u64 = ["can0", "can1"]
                .iter()
                .map(|b| meta["buses"][b]["frames"].as_u64().unwrap())
                .sum();
            assert_eq!(per_bus, file.frames);
            all.extend(read);
        }
        assert_eq!(all, (0..60_000).collect::<Vec<_>>());
    }

    #[test]
    fn a_file_per_bus_holds_that_bus_and_a_span_rotates_a_quiet_bus() {
        let scratch = folder("per-bus");
        let dir = scratch.path();
        let mut config = config(dir, Format::Asc, Layout::PerBus);
        config.rotation.max_span_ns = Some(1_000 * MS);
        let mut recorder = Recorder::new(config).unwrap();
        for i in 0..500 {
            recorder.record(record(i, 2)).unwrap();
        }
        // Nothing more comes; the clock passes the span.
        recorder.tick(START + 1_200 * MS).unwrap();
        assert_eq!(recorder.finished().len(), 2);
        for file in recorder.finished() {
            let bus = if file.path.to_string_lossy().ends_with("can0.asc") {
                0
            } else {
                1
            };
            let read = numbers(&file.path);
            assert_eq!(read, (0..500).filter(|i| i % 2 == bus).collect::<Vec<_>>());
        }
        assert!(recorder.finish().unwrap().len() == 2);
    }

    #[test]
    fn a_trigger_keeps_the_window_around_it_and_holds_no_more_than_asked() {
        let scratch = folder("window");
        let dir = scratch.path();
        let mut config = config(dir, Format::Mf4, Layout::Merged);
        config.window = Some(Window {
            before_ns: 1_000 * MS,
            after_ns: 500 * MS,
            max_held: 100_000,
        });
        let mut recorder = Recorder::new(config).unwrap();
        for i in 0..10_000u64 {
            if i == 5_000 {
                recorder
                    .trigger(START + i * MS, "WatchdogLevel >= 3")
                    .unwrap();
            }
            if i == 8_000 || i == 8_100 {
                recorder.trigger(START + i * MS, "bus-off").unwrap();
            }
            recorder.record(record(i, 1)).unwrap();
        }
        let files = recorder.finish().unwrap();
        assert_eq!(files.len(), 2, "{files:?}");
        assert_eq!(numbers(&files[0].path), (4_000..=5_500).collect::<Vec<_>>());
        // The second trigger extends the first's window.
        assert_eq!(numbers(&files[1].path), (7_000..=8_600).collect::<Vec<_>>());
        let meta = metadata(&files[1].path);
        assert_eq!(meta["triggers"].as_array().unwrap().len(), 1);
        assert_eq!(meta["triggers"][0]["reason"], "bus-off");

        let mut config = self::config(dir, Format::Candump, Layout::Merged);
        config.name = "small".into();
        config.window = Some(Window {
            before_ns: 10_000 * MS,
            after_ns: 0,
            max_held: 50,
        });
        let mut recorder = Recorder::new(config).unwrap();
        for i in 0..1_000 {
            recorder.record(record(i, 1)).unwrap();
        }
        assert_eq!(recorder.progress().held, 50);
        assert_eq!(recorder.progress().held_overflow, 950);
        recorder.trigger(START + 999 * MS, "key").unwrap();
        let files = recorder.finish().unwrap();
        assert_eq!(numbers(&files[0].path), (950..1_000).collect::<Vec<_>>());
    }

    #[test]
    fn a_recorder_that_dies_leaves_files_read_up_to_the_last_checkpoint() {
        for format in [Format::Blf, Format::Mf4, Format::Candump, Format::Pcapng] {
            let scratch = folder(&format!("cut-{format:?}"));
            let dir = scratch.path();
            let mut recorder = Recorder::new(config(dir, format, Layout::Merged)).unwrap();
            for i in 0..3_000 {
                recorder.record(record(i, 1)).unwrap();
            }
            recorder.tick(START + 3_000 * MS).unwrap();
            for i in 3_000..9_000 {
                recorder.record(record(i, 1)).unwrap();
            }
            let path = recorder.open.values().next().unwrap().facts.path.clone();
            // As a kill: nothing more is written, nothing is finished.
            std::mem::forget(recorder);
            let read = numbers(&path);
            assert!(read.len() >= 3_000, "{format:?}: {}", read.len());
            assert_eq!(read, (0..read.len() as u64).collect::<Vec<_>>());
            let meta = metadata(&path);
            assert_eq!(meta["status"], "recording");
            assert_eq!(meta["frames"], 3_000);
        }
    }

    #[test]
    fn a_file_killed_as_soon_as_it_is_begun_reads_as_an_empty_log() {
        for (format, _) in Format::ALL {
            if !format.survives_a_cut() || (format == Format::Mcap && !cfg!(feature = "mcap")) {
                continue;
            }
            let scratch = folder(&format!("begun-{format:?}"));
            let dir = scratch.path();
            let mut recorder = Recorder::new(config(dir, format, Layout::Merged)).unwrap();
            recorder.record(record(0, 1)).unwrap();
            let path = recorder.open.values().next().unwrap().facts.path.clone();
            std::mem::forget(recorder);
            let (_, records) = Format::open_file(&path).unwrap();
            let read: Vec<_> = records.collect();
            // MCAP's next chunk may have begun on disk (its length still a placeholder): the
            // reader stops there with an error, after what was checkpointed.
            if format != Format::Mcap {
                assert!(read.iter().all(Result::is_ok), "{format:?}: {read:?}");
            }
            assert!(read.iter().filter(|r| r.is_ok()).count() <= 1, "{format:?}");
        }
    }

    #[test]
    fn a_log_appears_under_its_name_only_with_its_metadata_beside_it() {
        let scratch = folder("sidecar-first");
        let dir = scratch.path();
        // Its metadata cannot be written: the temporary file's name is taken by a folder.
        std::fs::create_dir(dir.join("run-0001.blf.json.tmp")).unwrap();
        let mut recorder = Recorder::new(config(dir, Format::Blf, Layout::Merged)).unwrap();
        assert!(recorder.record(record(0, 1)).is_err());
        // Only the folder in the way: no log, no metadata, no partial file.
        assert_eq!(names(dir), ["run-0001.blf.json.tmp"]);
    }

    #[test]
    fn a_file_already_there_is_neither_overwritten_nor_given_new_metadata() {
        for taken in ["run-0001.blf", "run-0001.blf.json", ".run-0001.blf.part"] {
            let scratch = folder("taken");
            let dir = scratch.path();
            std::fs::write(dir.join(taken), "kept").unwrap();
            let mut recorder = Recorder::new(config(dir, Format::Blf, Layout::Merged)).unwrap();
            let error = recorder.record(record(0, 1)).unwrap_err();
            assert_eq!(error.kind(), io::ErrorKind::AlreadyExists);
            let text = error.to_string();
            assert!(text.contains(&format!("{taken} exists")), "{text}");
            assert_eq!(std::fs::read_to_string(dir.join(taken)).unwrap(), "kept");
            assert_eq!(names(dir), [taken], "{taken}");
        }
    }

    #[test]
    fn a_folder_that_cannot_be_written_is_refused_at_once() {
        let config = config(
            Path::new("/nonexistent/bywire"),
            Format::Blf,
            Layout::Merged,
        );
        let error = Recorder::new(config).err().unwrap().to_string();
        assert!(error.contains("/nonexistent/bywire"), "{error}");
    }
}
