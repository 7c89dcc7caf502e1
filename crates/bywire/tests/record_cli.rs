//! `bywire record` against real peers: the kernel's SJA1000 driver and vcan (listen-only set,
//! said and undone) inside `../shared/tools/canvm.sh`; python-can reading what a recording
//! killed with SIGKILL left; cantools decoding the frames around a signal trigger; the
//! simulated tug's served buses (`bywire sim --serve`, socketcand) as the traffic.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

mod common;

use std::io::{BufRead, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use common::{bywire, in_canvm, inside_lonet, Background, Scratch};

fn folder(test: &str) -> Scratch {
    Scratch::new(&format!("record-{test}"))
}

/// The simulated tug serving its buses over socketcand for `seconds`: (process, port).
fn served_tug(dir: &Path, seconds: u32) -> (Child, u16) {
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let mut sim = Command::new(env!("CARGO_BIN_EXE_bywire"))
        .args([
            "sim",
            "--no-view",
            "--max-seconds",
            &seconds.to_string(),
            "--serve",
        ])
        .arg(format!("127.0.0.1:{port}"))
        .arg("--out")
        .arg(dir.join("sim"))
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdout = std::io::BufReader::new(sim.stdout.take().unwrap());
    let mut first = String::new();
    stdout.read_line(&mut first).unwrap();
    assert!(first.starts_with("serving bus1"), "{first}");
    // The rest of its output is read, so it never writes to a closed pipe.
    std::thread::spawn(move || std::io::copy(&mut stdout, &mut std::io::sink()));
    (sim, port)
}

fn metadata(file: &Path) -> serde_json::Value {
    let mut name = file.as_os_str().to_owned();
    name.push(".json");
    serde_json::from_str(&std::fs::read_to_string(name).unwrap()).unwrap()
}

fn files_with(dir: &Path, extension: &str) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == extension))
        .collect();
    files.sort();
    files
}

fn python(script: &str) -> serde_json::Value {
    let out = Command::new("python3")
        .args(["-c", script])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn a_recording_killed_with_sigkill_leaves_files_python_can_reads() {
    let dir = folder("kill");
    let (mut sim, port) = served_tug(&dir, 20);
    let bus = |name: &str| format!("socketcand:127.0.0.1:{port}/{name}");
    let start = |out: &str, extra: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_bywire"))
            .args([
                "record",
                &bus("bus1"),
                &bus("bus2"),
                "--quiet",
                "--checkpoint",
                "300ms",
            ])
            .arg("--out")
            .arg(dir.join(out))
            .args(extra)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap()
    };
    // A file per bus in BLF, rotated by size; one merged MF4 file, never rotated.
    let mut blf = start("blf", &["--rotate-size", "16k"]);
    let mut mf4 = start("mf4", &["--format", "mf4", "--merged"]);
    std::thread::sleep(Duration::from_secs(4));
    blf.kill().unwrap();
    mf4.kill().unwrap();
    blf.wait().unwrap();
    mf4.wait().unwrap();
    sim.kill().unwrap();
    sim.wait().unwrap();

    let blfs = files_with(&dir.join("blf"), "blf");
    let mf4s = files_with(&dir.join("mf4"), "mf4");
    assert!(blfs.len() >= 4, "rotated BLF files: {blfs:?}");
    assert_eq!(mf4s.len(), 1, "{mf4s:?}");
    let list = |files: &[PathBuf]| {
        files
            .iter()
            .map(|f| format!("{:?}", f.to_str().unwrap()))
            .collect::<Vec<_>>()
            .join(",")
    };
    let read = python(&format!(
        r#"
import can, json
counts = {{}}
for path in [{}]:
    counts[path] = sum(1 for _ in can.BLFReader(path))
for path in [{}]:
    counts[path] = sum(1 for m in can.MF4Reader(path) if not m.is_error_frame)
print(json.dumps(counts))
"#,
        list(&blfs),
        list(&mf4s)
    ));
    let (mut cut, mut cut_with_frames) = (Vec::new(), 0);
    for file in blfs.iter().chain(&mf4s) {
        let meta = metadata(file);
        let read = read[file.to_str().unwrap()].as_u64().unwrap();
        let noted = meta["frames"].as_u64().unwrap();
        match meta["status"].as_str().unwrap() {
            // Finished at a rotation: every frame it says it has.
            "complete" => assert_eq!(read, noted, "{}", file.display()),
            // Open at the kill: at least what its last checkpoint noted
            // (nothing, for a file begun at a rotation since).
            "recording" => {
                cut.push(file.extension().unwrap().to_str().unwrap());
                cut_with_frames += usize::from(noted > 0);
                assert!(read >= noted, "{}: {read} < {noted}", file.display());
            }
            other => panic!("{other}"),
        }
    }
    // Each recorder left its open files cut: the MF4 file always (it is never rotated), and at
    // least one of the two buses' BLF files (the other's may have just been finished at a
    // rotation and its successor not be in place yet: a file is begun with the bus's next frame
    // and appears once its header and metadata are on disk).
    let cut_blf = cut.iter().filter(|e| **e == "blf").count();
    assert!(cut.contains(&"mf4") && cut_blf >= 1, "{cut:?}");
    // The merged MF4 file is never rotated: its checkpoints count its frames.
    assert!(cut_with_frames >= 1, "{cut_with_frames}");
}

#[test]
fn a_signal_trigger_keeps_the_window_around_it_as_cantools_decodes_it() {
    let dir = folder("trigger");
    let (mut sim, port) = served_tug(&dir, 20);
    let out = dir.join("logs");
    // The tug starts at rest: the capture begins when it first moves faster than 0.3 m/s.
    let (code, stdout, stderr) = bywire(
        &[
            "record",
            &format!("socketcand:127.0.0.1:{port}/bus1"),
            "--out",
            out.to_str().unwrap(),
            "--merged",
            "--profile",
            "reference-tug",
            "--pre",
            "500ms",
            "--post",
            "300ms",
            "--trigger",
            "VehicleToAds_State.VelocityActual > 0.3",
            "--duration",
            "12s",
            "--quiet",
        ],
        "",
    );
    sim.kill().unwrap();
    sim.wait().unwrap();
    assert_eq!(code, 0, "{stderr}");
    let files = files_with(&out, "blf");
    assert!(!files.is_empty(), "{stdout}{stderr}");
    let meta = metadata(&files[0]);
    assert_eq!(meta["status"], "complete");
    assert_eq!(
        meta["triggers"][0]["reason"],
        "VehicleToAds_State.VelocityActual > 0.3"
    );
    let trigger_s = meta["triggers"][0]["at_ns"].as_u64().unwrap() as f64 / 1e9;
    let dbc = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../bywire-tug/dbc/reference-tug.dbc"
    );
    let seen = python(&format!(
        r#"
import can, cantools, json
db = cantools.database.load_file({dbc:?}, strict=False)
state = db.get_message_by_name("VehicleToAds_State")
times, before, first_fast = [], [], None
for m in can.BLFReader({file:?}):
    times.append(m.timestamp)
    if m.arbitration_id == state.frame_id:
        v = state.decode(m.data)["VelocityActual"]
        if v > 0.3 and first_fast is None:
            first_fast = m.timestamp
        if first_fast is None:
            before.append(v)
print(json.dumps({{"first": times[0], "last": times[-1], "first_fast": first_fast,
                   "slow_before": all(v <= 0.3 for v in before), "frames": len(times)}}))
"#,
        file = files[0].to_str().unwrap()
    ));
    // The trigger is the first frame cantools decodes as faster, to the file's resolution.
    assert!(
        (seen["first_fast"].as_f64().unwrap() - trigger_s).abs() < 1e-5,
        "{seen} {trigger_s}"
    );
    assert_eq!(seen["slow_before"], true, "{seen}");
    // The window opens no more than --pre before it (and the bus had frames in all of it).
    let pre = trigger_s - seen["first"].as_f64().unwrap();
    assert!(pre <= 0.5 + 1e-3 && pre > 0.4, "pre {pre}");
    assert_eq!(seen["frames"], meta["frames"]);
}

#[test]
fn a_key_press_captures_the_window_and_stops_cleanly_on_ctrl_c() {
    let dir = folder("key");
    let (mut sim, port) = served_tug(&dir, 20);
    let out = dir.join("logs");
    let mut recorder = Command::new(env!("CARGO_BIN_EXE_bywire"))
        .args(["record", &format!("socketcand:127.0.0.1:{port}/bus3")])
        .arg("--out")
        .arg(&out)
        .args([
            "--format",
            "asc",
            "--pre",
            "1s",
            "--post",
            "1s",
            "--trigger",
            "key",
        ])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_secs(3));
    recorder.stdin.as_mut().unwrap().write_all(b"\n").unwrap();
    std::thread::sleep(Duration::from_secs(3));
    let _ = Command::new("kill")
        .args(["-INT", &recorder.id().to_string()])
        .status();
    let done = recorder.wait_with_output().unwrap();
    sim.kill().unwrap();
    sim.wait().unwrap();
    assert!(
        done.status.success(),
        "{}",
        String::from_utf8_lossy(&done.stderr)
    );
    let status = String::from_utf8_lossy(&done.stderr);
    assert!(status.contains("no controller to set"), "{status}");
    assert!(status.contains("fr/s"), "the status line: {status}");
    let files = files_with(&out, "asc");
    assert_eq!(files.len(), 1, "{files:?}");
    let meta = metadata(&files[0]);
    assert_eq!(meta["triggers"][0]["reason"], "key");
    let first = meta["first_frame_ns"].as_u64().unwrap() as f64 / 1e9;
    let last = meta["last_frame_ns"].as_u64().unwrap() as f64 / 1e9;
    let at = meta["triggers"][0]["at_ns"].as_u64().unwrap() as f64 / 1e9;
    assert!(at - first <= 1.0 + 1e-3 && at - first > 0.8, "{meta}");
    assert!(last - at <= 1.0 + 1e-3 && last - at > 0.8, "{meta}");
    // The file reads as python-can reads ASC: every frame its metadata counts.
    let read = python(&format!(
        "import can, json; print(json.dumps(sum(1 for _ in can.ASCReader({:?}))))",
        files[0].to_str().unwrap()
    ));
    assert_eq!(read, meta["frames"]);
}

/// python-can sends frames and then an error frame with the bus-off class over
/// `udp_multicast` (inside lonet): the error-frame and bus-off triggers both capture it.
#[test]
fn error_frames_and_bus_off_from_python_can_trigger_a_capture() {
    if !inside_lonet("error_frames_and_bus_off_from_python_can_trigger_a_capture") {
        return;
    }
    let dir = folder("errors");
    let out = dir.join("logs");
    let recorder = Background::start(&[
        "record",
        "udp:239.74.163.2:43580",
        "--out",
        out.to_str().unwrap(),
        "--format",
        "candump",
        "--merged",
        "--pre",
        "300ms",
        "--post",
        "300ms",
        "--trigger",
        "error-frame",
        "--trigger",
        "bus-off",
        "--quiet",
    ]);
    std::thread::sleep(Duration::from_millis(500));
    let sent = python(
        r#"
import can, json, time
bus = can.Bus(interface="udp_multicast", channel="239.74.163.2", port=43580)
for i in range(150):
    bus.send(can.Message(arbitration_id=0x123, data=[i % 256], is_extended_id=False))
    time.sleep(0.01)
bus.send(can.Message(arbitration_id=0x40, is_error_frame=True, dlc=8, data=[0] * 8, is_extended_id=False))
for i in range(150):
    bus.send(can.Message(arbitration_id=0x124, data=[i % 256], is_extended_id=False))
    time.sleep(0.01)
bus.shutdown()
print(json.dumps("sent"))
"#,
    );
    assert_eq!(sent, "sent");
    let (code, _, stderr) = recorder.stop();
    assert_eq!(code, 0, "{stderr}");
    let files = files_with(&out, "log");
    assert_eq!(files.len(), 1, "{files:?} {stderr}");
    let meta = metadata(&files[0]);
    let reasons: Vec<&str> = meta["triggers"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| t["reason"].as_str().unwrap())
        .collect();
    assert_eq!(
        reasons,
        [
            "error frame on udp:239.74.163.2:43580",
            "bus-off on udp:239.74.163.2:43580"
        ]
    );
    let log = std::fs::read_to_string(&files[0]).unwrap();
    let lines: Vec<&str> = log.lines().collect();
    // About 300 ms of frames each side of the error frame (10 ms apart), and nothing else.
    let before = lines
        .iter()
        .take_while(|l| !l.contains("#R") && l.contains(" 123#"))
        .count();
    let after = lines.iter().filter(|l| l.contains(" 124#")).count();
    assert!((20..=32).contains(&before), "{before}: {log}");
    assert!((20..=32).contains(&after), "{after}: {log}");
    assert!(log.contains("20000040#"), "the error frame itself: {log}");
    assert_eq!(lines.len(), before + after + 1, "{log}");
}

#[test]
fn listen_only_is_set_on_a_controller_said_for_vcan_and_undone_after() {
    let bin = env!("CARGO_BIN_EXE_bywire");
    let script = format!(
        r#"
for i in 0 1 2; do ip link set can$i type can bitrate 500000 && ip link set can$i up; done
# Every bus is open once the recorder has said how it listens on the last one.
said() {{ for i in $(seq 300); do grep -q "^$1: " $2 2>/dev/null && return; sleep 0.05; done; }}
mkdir -p /tmp/r
{bin} record can0 vcan0 --out /tmp/r --format candump --duration 4s --quiet > /tmp/r/out.txt 2> /tmp/r/err.txt &
said vcan0 /tmp/r/err.txt
echo "during: $(ip -details link show can0 | grep -c LISTEN-ONLY)"
for i in 1 2 3 4 5; do cansend can1 123#DEADBEEF0$i; done
cansend vcan0 456#01
wait
echo "after: $(ip -details link show can0 | grep -c LISTEN-ONLY)"
echo "up: $(ip link show can0 | grep -c 'state UP')"
cat /tmp/r/err.txt /tmp/r/*.log
{bin} record can0 --shared --out /tmp/s --duration 1s --quiet 2> /tmp/shared.txt > /dev/null &
said can0 /tmp/shared.txt
echo "shared: $(ip -details link show can0 | grep -c LISTEN-ONLY)"
wait
cat /tmp/shared.txt
"#
    );
    let text = in_canvm(
        &["--sja1000", "3", "--can-utils", "--include", bin],
        &script,
    );
    assert!(text.contains("during: 1"), "{text}");
    assert!(
        text.contains("after: 0") && text.contains("up: 1"),
        "{text}"
    );
    assert!(text.contains("shared: 0"), "{text}");
    assert!(
        text.contains("can0: listen-only (switched for this recording)"),
        "{text}"
    );
    assert!(text.contains("vcan0: no controller to set"), "{text}");
    for i in 1..=5 {
        assert!(text.contains(&format!(" can0 123#DEADBEEF0{i}")), "{text}");
    }
    assert!(text.contains(" vcan0 456#01"), "{text}");
}

#[test]
fn bad_options_are_named_before_any_bus_is_opened() {
    let dir = folder("bad");
    let out = dir.to_str().unwrap();
    let cases: [(&[&str], &str); 8] = [
        (&["--format", "xls"], "--format xls"),
        (
            &["--format", "mf4", "--compression", "snappy"],
            "--compression is for Parquet output; --format mf4",
        ),
        (&["--pre", "5s"], "give at least one --trigger"),
        (
            &["--trigger", "VehicleToAds_State.Speed > 1"],
            "--dbc or --profile",
        ),
        (
            &[
                "--profile",
                "reference-tug",
                "--trigger",
                "VehicleToAds_State.Speed > 1",
            ],
            "has no signal 'Speed'",
        ),
        (
            &[
                "--profile",
                "reference-tug",
                "--trigger",
                "VehicleToAds_State.ControlMode == Flying",
            ],
            "no value named 'Flying'",
        ),
        (&["--rotate-size", "10"], "at least 4 KiB"),
        (&["--rotate-time", "3 weeks"], "unit"),
    ];
    for (extra, expected) in cases {
        let mut args = vec!["record", "virtual:nothing", "--out", out];
        args.extend(extra);
        let (code, _, stderr) = bywire(&args, "");
        assert_ne!(code, 0, "{extra:?}");
        assert!(stderr.contains(expected), "{extra:?}: {stderr}");
    }
    let (code, _, stderr) = bywire(&["record", "virtual:x", "--out", "/proc/no/such"], "");
    assert_ne!(code, 0);
    assert!(stderr.contains("/proc/no/such"), "{stderr}");
}

/// MCAP recordings killed with SIGKILL at 20 random moments: every chunk closed before the
/// kill reads back, in the `mcap` Python reader and in ours alike (ours warns that the file is
/// cut short), and at least the frames the last checkpoint noted. Before, a chunk was begun
/// with a placeholder length written over only when it closed, so a killed recording's file
/// read as nothing (8 of 8 kills).
#[test]
fn mcap_recordings_killed_at_random_moments_keep_every_closed_chunk() {
    let dir = folder("kill-mcap");
    let (mut sim, port) = served_tug(&dir, 60);
    let bus = format!("socketcand:127.0.0.1:{port}/bus1");
    let seed = fastrand::u64(..);
    let mut random = fastrand::Rng::with_seed(seed);
    let mut files = Vec::new();
    for batch in 0..4 {
        let runs: Vec<(Child, Duration, PathBuf)> = (0..5)
            .map(|k| {
                let out = dir.join(format!("mcap-{batch}-{k}"));
                let child = Command::new(env!("CARGO_BIN_EXE_bywire"))
                    .args(["record", &bus, "--quiet", "--merged", "--format", "mcap"])
                    .args(["--checkpoint", "200ms", "--out"])
                    .arg(&out)
                    .stdout(Stdio::null())
                    .stderr(Stdio::null())
                    .spawn()
                    .unwrap();
                let after = Duration::from_millis(random.u64(300..2500));
                (child, after, out)
            })
            .collect();
        let start = std::time::Instant::now();
        for (mut child, after, out) in runs {
            std::thread::sleep(after.saturating_sub(start.elapsed()));
            child.kill().unwrap();
            child.wait().unwrap();
            if out.exists() {
                files.extend(files_with(&out, "mcap"));
            }
        }
    }
    sim.kill().unwrap();
    sim.wait().unwrap();
    let with_frames: Vec<&PathBuf> = files
        .iter()
        .filter(|f| metadata(f)["frames"].as_u64().unwrap() > 0)
        .collect();
    assert!(with_frames.len() >= 10, "seed {seed}: {files:?}");
    let list = files
        .iter()
        .map(|f| format!("{:?}", f.to_str().unwrap()))
        .collect::<Vec<_>>()
        .join(",");
    let theirs = python(&format!(
        r#"
import json
from mcap.reader import NonSeekingReader
from mcap.exceptions import EndOfFile
counts = {{}}
for path in [{list}]:
    n = 0
    with open(path, "rb") as f:
        try:
            for _ in NonSeekingReader(f).iter_messages(log_time_order=False):
                n += 1
        except EndOfFile:
            pass
    counts[path] = n
print(json.dumps(counts))
"#
    ));
    for file in &files {
        let name = file.to_str().unwrap();
        let (code, out, err) = bywire(&["log", "stats", name], "");
        assert_eq!(code, 0, "seed {seed}: {name}: {err}");
        let ours: u64 = out.split_whitespace().next().unwrap().parse().unwrap();
        let noted = metadata(file)["frames"].as_u64().unwrap();
        assert_eq!(ours, theirs[name].as_u64().unwrap(), "seed {seed}: {name}");
        assert!(ours >= noted, "seed {seed}: {name}: {ours} < {noted}");
        if metadata(file)["status"] == "recording" && !err.is_empty() {
            assert!(err.contains("the file is cut short there"), "{err}");
        }
    }
}
