//! The recorder (`bywire record`'s core) writing four buses, a file each, in BLF and MF4.
//!
//! - `record/*`: the recorder's own cost, frames a second on one core, from frames in memory
//!   (8-byte standard frames, four buses, checkpoints every 2 s of their time).
//! - then, once, a live run: four `sim:` buses at 1 Mbit/s kept at 100 % load by a sender each
//!   for 3 s, a reader thread each, the recorder on one thread; it prints the frames sent,
//!   recorded and dropped, and the recorder thread's CPU time against the wall time.
#![allow(
    missing_docs,
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::cast_precision_loss,
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss
)]

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{mpsc, Arc};
use std::time::{Duration, Instant};

use bywire_core::{Frame, Id, Timestamp};
use bywire_log::format::{Format, ParquetCompression};
use bywire_log::recorder::{Config, Layout, Recorder, Rotation};
use bywire_log::LogRecord;
use criterion::{criterion_group, criterion_main, Criterion, Throughput};

const FRAMES: u64 = 200_000;
const BUSES: u64 = 4;

fn folder(name: &str) -> PathBuf {
    let dir =
        std::env::temp_dir().join(format!("bywire-bench-record-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn config(dir: PathBuf, format: Format, name: String) -> Config {
    Config {
        dir,
        name,
        format,
        compression: ParquetCompression::default(),
        layout: Layout::PerBus,
        rotation: Rotation::default(),
        checkpoint_ns: 2_000_000_000,
        window: None,
        metadata: serde_json::Map::new(),
    }
}

fn record(i: u64) -> LogRecord {
    LogRecord {
        // Four buses at about 8,000 frames a second each.
        timestamp: Timestamp::from_nanos(1_700_000_000_000_000_000 + i * 31_250),
        interface: format!("can{}", i % BUSES),
        frame: Frame::classic(
            Id::standard(0x100 + (i % 64) as u32).unwrap(),
            &i.to_le_bytes(),
        )
        .unwrap(),
        direction: Some('R'),
    }
}

fn throughput(c: &mut Criterion) {
    let records: Vec<LogRecord> = (0..FRAMES).map(record).collect();
    let mut group = c.benchmark_group("record");
    group.throughput(Throughput::Elements(FRAMES));
    group.sample_size(10);
    for (format, name) in [(Format::Blf, "blf"), (Format::Mf4, "mf4")] {
        let dir = folder(name);
        let mut run = 0u32;
        group.bench_function(format!("4 buses/{name}"), |b| {
            b.iter(|| {
                run += 1;
                let mut recorder =
                    Recorder::new(config(dir.clone(), format, format!("run{run}"))).unwrap();
                let mut now = 0;
                for (i, r) in records.iter().enumerate() {
                    recorder.record(r.clone()).unwrap();
                    if i % 1024 == 0 {
                        now = r.timestamp.as_nanos();
                        recorder.tick(now).unwrap();
                    }
                }
                recorder.tick(now).unwrap();
                recorder.finish().unwrap()
            });
        });
        let _ = std::fs::remove_dir_all(&dir);
    }
    group.finish();
}

/// The calling thread's CPU time (user and system), from /proc.
fn thread_cpu() -> Duration {
    let stat = std::fs::read_to_string("/proc/thread-self/stat").unwrap_or_default();
    let fields: Vec<&str> = stat
        .rsplit(')')
        .next()
        .unwrap_or("")
        .split_whitespace()
        .collect();
    let ticks: u64 = fields.get(11).and_then(|u| u.parse().ok()).unwrap_or(0)
        + fields.get(12).and_then(|s| s.parse().ok()).unwrap_or(0);
    Duration::from_millis(ticks * 10)
}

fn live(format: Format, name: &str) {
    let run_for = Duration::from_secs(3);
    let stop = Arc::new(AtomicBool::new(false));
    let sent = Arc::new(AtomicU64::new(0));
    let (tx, rx) = mpsc::sync_channel::<LogRecord>(16_384);
    let mut threads = Vec::new();
    let mut readers = Vec::new();
    for bus in 0..BUSES {
        let spec = format!("sim:bench-{name}-{bus}@1000000");
        let mut receiver = bywire_bus::open(&spec).unwrap();
        receiver.set_receive_own(false).unwrap();
        let mut sender = bywire_bus::open(&spec).unwrap();
        let (stop_s, sent) = (Arc::clone(&stop), Arc::clone(&sent));
        threads.push(std::thread::spawn(move || {
            // About 120 bits a frame: 9 a millisecond keeps the controller's queue from
            // emptying (the bus at 100 %); the queue grows by under one frame a millisecond.
            let begun = Instant::now();
            let mut i = 0u64;
            while !stop_s.load(Ordering::Relaxed) {
                let due = (begun.elapsed().as_micros() as u64) * 9 / 1000 + 1;
                while i < due {
                    let frame = Frame::classic(
                        Id::standard(0x100 + (i % 64) as u32).unwrap(),
                        &i.wrapping_mul(0x9E37_79B9_7F4A_7C15).to_le_bytes(),
                    )
                    .unwrap();
                    sender.send(&frame).unwrap();
                    i += 1;
                }
                std::thread::sleep(Duration::from_micros(500));
            }
            sent.fetch_add(i, Ordering::Relaxed);
            // Kept until the frames it queued have left (a closed endpoint's queue goes).
            sender
        }));
        let tx = tx.clone();
        let stop_r = Arc::clone(&stop);
        readers.push(std::thread::spawn(move || {
            let mut quiet_since: Option<Instant> = None;
            loop {
                match receiver.recv(Some(Duration::from_millis(50))).unwrap() {
                    Some(received) => {
                        quiet_since = None;
                        tx.send(LogRecord {
                            timestamp: received.timestamp,
                            interface: format!("can{bus}"),
                            frame: received.frame,
                            direction: Some('R'),
                        })
                        .unwrap();
                    }
                    // After the senders stop, the queued frames drain; then it is over.
                    None if stop_r.load(Ordering::Relaxed) => {
                        let since = *quiet_since.get_or_insert_with(Instant::now);
                        if since.elapsed() > Duration::from_millis(300) {
                            return receiver.stats().rx_dropped;
                        }
                    }
                    None => {}
                }
            }
        }));
    }
    drop(tx);
    let dir = folder(&format!("live-{name}"));
    let recorder_dir = dir.clone();
    let recording = std::thread::spawn(move || {
        let mut recorder = Recorder::new(config(recorder_dir, format, "live".into())).unwrap();
        let cpu = thread_cpu();
        let wall = Instant::now();
        let mut recorded = 0u64;
        let mut last_tick = Instant::now();
        for record in rx {
            recorder.record(record).unwrap();
            recorded += 1;
            if last_tick.elapsed() >= Duration::from_millis(20) {
                last_tick = Instant::now();
                recorder.tick(wall.elapsed().as_nanos() as u64).unwrap();
            }
        }
        let files = recorder.finish().unwrap();
        let written: u64 = files.iter().map(|f| f.frames).sum();
        (recorded, written, thread_cpu() - cpu, wall.elapsed())
    });
    std::thread::sleep(run_for);
    stop.store(true, Ordering::Relaxed);
    let senders: Vec<_> = threads.into_iter().map(|t| t.join().unwrap()).collect();
    let dropped: u64 = readers.into_iter().map(|r| r.join().unwrap()).sum();
    drop(senders);
    let (recorded, written, cpu, wall) = recording.join().unwrap();
    let sent = sent.load(Ordering::Relaxed);
    println!(
        "live {name}: 4 buses at 1 Mbit/s, 100 % load for {:.1} s: sent {sent}, recorded {recorded}, in files {written}, dropped {dropped}, lost {}; recorder thread CPU {:.2} s of {:.2} s wall ({:.0} %)",
        run_for.as_secs_f64(),
        sent - written.min(sent),
        cpu.as_secs_f64(),
        wall.as_secs_f64(),
        100.0 * cpu.as_secs_f64() / wall.as_secs_f64()
    );
    let _ = std::fs::remove_dir_all(&dir);
}

fn live_runs(_: &mut Criterion) {
    live(Format::Blf, "blf");
    live(Format::Mf4, "mf4");
}

criterion_group!(benches, throughput, live_runs);
criterion_main!(benches);
