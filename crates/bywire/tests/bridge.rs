//! `bywire bridge` end to end: JSON commands streamed in real time to the ADS side, a simulated
//! vehicle (the real supervisor) on the same bit-timed bus, vehicle state out as JSON lines.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

mod common;

use common::Scratch;

use std::io::{BufRead, BufReader, Write};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use serde_json::Value;

/// What a bridge run wrote: its JSON lines (states and events) and its standard error.
struct Run {
    lines: Vec<Value>,
    stderr: String,
}

impl Run {
    /// The state lines.
    fn states(&self) -> Vec<&Value> {
        self.lines
            .iter()
            .filter(|l| l.get("mode").is_some())
            .collect()
    }
}

/// The engage an operator sends.
const ENGAGE: &str = r#"{"engage": true}"#;

/// A bridge started with `args`: its stdout read as JSON lines on a thread, `seen` set once a
/// state line shows `reached`.
struct Started {
    child: std::process::Child,
    stdin: std::process::ChildStdin,
    reader: std::thread::JoinHandle<Vec<Value>>,
    seen: Arc<AtomicBool>,
}

impl Started {
    fn new(args: &[&str], reached: impl Fn(&Value) -> bool + Send + 'static) -> Started {
        let mut child = Command::new(env!("CARGO_BIN_EXE_bywire"))
            .args(args)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let stdin = child.stdin.take().unwrap();
        let stdout = child.stdout.take().unwrap();
        let seen = Arc::new(AtomicBool::new(false));
        let reader = {
            let seen = Arc::clone(&seen);
            std::thread::spawn(move || {
                let mut lines = Vec::new();
                for line in BufReader::new(stdout).lines() {
                    let line: Value = serde_json::from_str(&line.unwrap()).unwrap();
                    if line.get("mode").is_some() && reached(&line) {
                        seen.store(true, Ordering::Relaxed);
                    }
                    lines.push(line);
                }
                lines
            })
        };
        Started {
            child,
            stdin,
            reader,
            seen,
        }
    }

    /// Close its input and wait for its end, which must be a success.
    fn finish(self) -> Run {
        drop(self.stdin);
        let lines = self.reader.join().unwrap();
        let out = self.child.wait_with_output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
        assert!(out.status.success(), "{stderr}");
        Run { lines, stderr }
    }
}

/// Run the bridge with `args`, writing `input(k)` for k = 0, 1, … one `every`: at least
/// `at_least` of them, and on until a state line shows `reached` (20 s at most). On, because a
/// loaded machine can stall the bridge long enough for the vehicle's watchdog to brake, or
/// delay its recovery past a scripted engage, which it refuses; the vehicle drives again only
/// after its recovery and another engage, as it should. The bridge must end well.
fn run_until(
    args: &[&str],
    at_least: usize,
    every: Duration,
    input: impl Fn(usize) -> Vec<u8>,
    reached: impl Fn(&Value) -> bool + Send + 'static,
) -> Run {
    let mut bridge = Started::new(args, reached);
    let deadline = Instant::now() + Duration::from_secs(20);
    let mut k = 0;
    while k < at_least || (!bridge.seen.load(Ordering::Relaxed) && Instant::now() < deadline) {
        // A bridge that ended early says why on its standard error (asserted below).
        if bridge.stdin.write_all(&input(k)).is_err() {
            break;
        }
        std::thread::sleep(every);
        k += 1;
    }
    bridge.finish()
}

/// `drive` every 25 ms with an engage every 0.5 s, for 2.5 s and on until a state shows
/// `reached` (see [`run_until`]); the states.
fn drive_until(args: &[&str], drive: &str, reached: fn(&Value) -> bool) -> Vec<Value> {
    let line = |k: usize| {
        let line = if k > 0 && k.is_multiple_of(20) {
            ENGAGE
        } else {
            drive
        };
        format!("{line}\n").into_bytes()
    };
    let run = run_until(args, 100, Duration::from_millis(25), line, reached);
    run.states().into_iter().cloned().collect()
}

#[test]
fn bridge_engages_a_simulated_vehicle_and_brakes_at_end_of_input() {
    // Commands must keep coming (a command older than 200 ms becomes a controlled stop).
    // (The vehicle accelerates at 1 m/s²: 1.5 m/s within two seconds of the engage.)
    let drive = r#"{"velocity": 1.5, "gear": "drive", "mode": "autonomous", "steering": 5.0}"#;
    let line = |k: usize| -> Vec<u8> {
        let line = match k {
            20 => ENGAGE,
            30 => "not json",
            40 => r#"{"velocity": 1000}"#,
            // A line that is not UTF-8 is refused, and the bridge goes on.
            50 => {
                let mut bytes = format!("{drive}\n").into_bytes();
                bytes.extend_from_slice(b"{\"velocity\": \xff}\n");
                return bytes;
            }
            // Past the script, the operator engages again until the vehicle drives.
            k if k >= 120 && k.is_multiple_of(20) => ENGAGE,
            _ => drive,
        };
        format!("{line}\n").into_bytes()
    };
    let run = run_until(
        &[
            "bridge",
            "--profile",
            "reference-tug",
            "sim:bridge-test@500000",
            "--with-vehicle",
            "--estop-on-eof",
            "--rate",
            "20",
        ],
        120,
        Duration::from_millis(25),
        line,
        |s| {
            s["mode"] == "autonomous"
                && s["velocity"] == 1.5
                && s["steering"]
                    .as_f64()
                    .is_some_and(|a| (a - 5.0).abs() < 0.05)
        },
    );
    let (lines, states) = (&run.lines, run.states());
    // Manual and braked at first (the vehicle fails closed), then autonomous at the commanded
    // speed with the steering reached.
    assert!(states
        .iter()
        .any(|s| s["mode"] == "manual" && s["watchdog_level"] == 4));
    let driving: Vec<&&Value> = states
        .iter()
        .filter(|s| s["mode"] == "autonomous" && s["velocity"] == 1.5)
        .collect();
    assert!(!driving.is_empty(), "never drove: {states:?}");
    assert!(driving
        .iter()
        .any(|s| (s["steering"].as_f64().unwrap() - 5.0).abs() < 0.05));
    // Real time on a shared machine: a late thread can age a frame past its timeout now and
    // then (the exact timing is tested in simulated time); most states must be fresh.
    let alive = driving
        .iter()
        .filter(|s| s["feedback_alive"] == true)
        .count();
    assert!(
        alive * 10 >= driving.len() * 8,
        "{alive} of {} fresh",
        driving.len()
    );
    let latency = driving.last().unwrap()["echo_latency_ms"].as_f64().unwrap();
    assert!(latency < 100.0, "{latency} ms");
    // The bad lines are reported with their numbers; the out-of-range one on stderr too, and
    // the vehicle never went faster than asked.
    let refused = |number: &str| {
        lines.iter().any(|l| {
            l["event"] == "bad_command" && l["detail"].as_str().unwrap().starts_with(number)
        })
    };
    assert!(
        refused("line 31:") && refused("line 41: velocity 1000") && refused("line 52: not UTF-8")
    );
    let err = &run.stderr;
    assert!(
        err.contains("line 41: velocity 1000: beyond ±5 m/s"),
        "{err}"
    );
    assert!(states
        .iter()
        .all(|s| s["velocity"].as_f64().unwrap_or(0.0) <= 1.5));
    // The end of input brakes.
    let end = lines
        .iter()
        .position(|l| l["event"] == "end_of_input")
        .unwrap();
    let after: Vec<&Value> = lines[end..]
        .iter()
        .filter(|l| l.get("velocity").is_some())
        .collect();
    assert!(after.last().unwrap()["velocity"] == 0.0, "{after:?}");
}

#[test]
fn bridge_refuses_bad_arguments_clearly() {
    let (code, _, err) = common::bywire(&["bridge", "--profile", "hovercraft", "virtual:x"], "");
    assert_eq!(code, 1);
    assert!(err.contains("no built-in profile 'hovercraft'"), "{err}");
    let (code, _, err) = common::bywire(&["bridge", "--profile", "autoware-can", "virtual:x"], "");
    assert_eq!(code, 1);
    assert!(err.contains("no [command] section"), "{err}");
    let (code, _, err) = common::bywire(
        &[
            "bridge",
            "--profile",
            "reference-tug",
            "socketcan:can9",
            "--with-vehicle",
        ],
        "",
    );
    assert_eq!(code, 1);
    assert!(err.contains("can9") || err.contains("in-process"), "{err}");
    // A plain name is a SocketCAN interface, as in every command.
    let (code, _, err) = common::bywire(&["bridge", "--profile", "reference-tug", "bus"], "");
    assert_eq!(code, 1);
    assert!(err.contains("socketcan:bus"), "{err}");
    let (code, _, err) = common::bywire(&["bridge", "--profile", "reference-tug", "nope:x"], "");
    assert_eq!(code, 1);
    assert!(err.contains("nope:x"), "{err}");
    // Without --estop-on-eof, the end of input just ends the bridge.
    let (code, out, _) = common::bywire(
        &["bridge", "--profile", "reference-tug", "virtual:quiet"],
        "",
    );
    assert_eq!(code, 0);
    assert!(!out.contains("end_of_input"));
}

#[test]
fn bridge_drives_over_two_redundant_buses() {
    let states = drive_until(
        &[
            "bridge",
            "--profile",
            "reference-tug",
            "sim:redundant-a@500000",
            "sim:redundant-b@500000",
            "--with-vehicle",
            "--rate",
            "20",
        ],
        r#"{"velocity": 1.0, "gear": "drive", "mode": "autonomous"}"#,
        |s| s["mode"] == "autonomous" && s["velocity"] == 1.0 && s["warning"] == false,
    );
    // Both copies agree: the vehicle drives, not degraded (no warning), and the feedback
    // that arrives twice is taken once (no counter rejections).
    let driving: Vec<&Value> = states
        .iter()
        .filter(|s| s["mode"] == "autonomous" && s["velocity"] == 1.0)
        .collect();
    assert!(!driving.is_empty(), "{states:?}");
    assert!(driving.iter().any(|s| s["warning"] == false));
    assert_eq!(states.last().unwrap()["rejected"]["counter"], 0);
}

/// Another vehicle's profile (profiles/shuttle of bywire-vehicle: its own identifiers,
/// big-endian setpoints, 8-bit counters, XOR checksums, its own enum numbers) drives that
/// vehicle's messages: python-can on the same socketcand-served bus plays the shuttle, with
/// cantools encoding its status (echoing the command counter) and decoding our commands.
#[test]
fn bridge_drives_another_vehicle_by_its_profile() {
    let data = format!("{}/../bywire-vehicle/profiles", env!("CARGO_MANIFEST_DIR"));
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let mut server = Command::new(env!("CARGO_BIN_EXE_bywire"))
        .args([
            "serve",
            "virtual:shuttle",
            "--listen",
            &format!("127.0.0.1:{port}"),
        ])
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut first = String::new();
    std::io::BufRead::read_line(
        &mut std::io::BufReader::new(server.stdout.as_mut().unwrap()),
        &mut first,
    )
    .unwrap();
    let script = format!(
        r#"
import can, cantools, time, json
from functools import reduce
db = cantools.database.load_file("{data}/shuttle.dbc")
bus = can.Bus(interface="socketcand", host="127.0.0.1", port={port}, channel="shuttle")
print("ready", flush=True)
commands, alive, end = [], 0, time.time() + 2.5
while time.time() < end:
    m = bus.recv(0.05)
    if m is None or m.arbitration_id != 1280:
        continue
    c = db.decode_message(1280, m.data, decode_choices=False)
    c["xor_ok"] = reduce(lambda a, b: a ^ b, m.data[:7], 0) == m.data[7]
    commands.append(c)
    data = bytearray(db.encode_message(1281, {{"St_Steer": c["Cmd_Steer"], "St_Speed": 2.25, "St_Mode": c["Cmd_Mode"], "St_SteerMode": c["Cmd_SteerMode"], "St_Echo": c["Cmd_Alive"], "St_Alive": alive % 256, "St_Xor": 0}}))
    data[7] = reduce(lambda a, b: a ^ b, data[:7], 0)
    bus.send(can.Message(arbitration_id=1281, is_extended_id=False, data=bytes(data)))
    alive += 1
last = commands[-1]
print(json.dumps({{"count": len(commands), "xor_ok": all(c["xor_ok"] for c in commands), "gear": last["Cmd_Gear"], "mode": last["Cmd_Mode"], "steer": last["Cmd_Steer"], "speed": last["Cmd_Speed"], "steer_mode": last["Cmd_SteerMode"]}}), flush=True)
bus.shutdown()
"#
    );
    let mut shuttle = Command::new("python3")
        .args(["-c", &script])
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut shuttle_out = std::io::BufReader::new(shuttle.stdout.take().unwrap());
    let mut ready = String::new();
    std::io::BufRead::read_line(&mut shuttle_out, &mut ready).unwrap();
    assert_eq!(ready.trim(), "ready");
    let mut bridge = Command::new(env!("CARGO_BIN_EXE_bywire"))
        .args([
            "bridge",
            "--profile",
            &format!("{data}/shuttle.toml"),
            &format!("socketcand:127.0.0.1:{port}/shuttle"),
            "--rate",
            "20",
        ])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdin = bridge.stdin.take().unwrap();
    for _ in 0..60 {
        writeln!(stdin, r#"{{"velocity": 2.5, "gear": "drive", "mode": "autonomous", "steering": -4.2, "steering_mode": "crab"}}"#).unwrap();
        std::thread::sleep(Duration::from_millis(25));
    }
    drop(stdin);
    let out = bridge.wait_with_output().unwrap();
    let mut report = String::new();
    std::io::Read::read_to_string(&mut shuttle_out, &mut report).unwrap();
    assert!(shuttle.wait().unwrap().success());
    let _ = server.kill();
    let _ = server.wait();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let shuttle_saw: Value = serde_json::from_str(report.trim()).unwrap();
    assert!(
        shuttle_saw["count"].as_u64().unwrap() >= 20,
        "{shuttle_saw}"
    );
    assert_eq!(shuttle_saw["xor_ok"], true);
    assert_eq!(
        (
            shuttle_saw["gear"].as_f64(),
            shuttle_saw["mode"].as_f64(),
            shuttle_saw["steer_mode"].as_f64()
        ),
        (Some(1.0), Some(2.0), Some(2.0)),
        "the shuttle's enum numbers"
    );
    assert!(
        (shuttle_saw["steer"].as_f64().unwrap() + 4.2).abs() < 0.006
            && (shuttle_saw["speed"].as_f64().unwrap() - 2.5).abs() < 0.001,
        "{shuttle_saw}"
    );
    // The bridge validated the shuttle's status frames by role: fresh, autonomous, its speed.
    let states: Vec<Value> = String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .filter(|l: &Value| l.get("mode").is_some())
        .collect();
    let alive: Vec<&Value> = states
        .iter()
        .filter(|s| s["feedback_alive"] == true)
        .collect();
    assert!(alive.len() >= 5, "{states:?}");
    let last = alive.last().unwrap();
    assert_eq!(
        (last["mode"].as_str(), last["velocity"].as_f64()),
        (Some("autonomous"), Some(2.25)),
        "{last}"
    );
    assert_eq!(last["rejected"]["checksum"], 0, "{last}");
    // The simulated vehicle speaks the profile too: the shuttle's supervisor engages.
    let line = |k: usize| {
        // Engaged at 0.5 s, and again every 0.8 s should the vehicle still recover then.
        let engage = if k == 12 || (k > 12 && k % 20 == 12) {
            r#", "engage": true"#
        } else {
            ""
        };
        format!("{{\"velocity\": 1.5, \"gear\": \"drive\", \"mode\": \"autonomous\"{engage}}}\n")
            .into_bytes()
    };
    let run = run_until(
        &[
            "bridge",
            "--profile",
            &format!("{data}/shuttle.toml"),
            "sim:shuttle-vehicle@500000",
            "--with-vehicle",
            "--rate",
            "20",
        ],
        80,
        Duration::from_millis(40),
        line,
        |s| s["mode"] == "autonomous" && s["velocity"] == 1.5,
    );
    let states = run.states();
    assert!(
        states
            .iter()
            .any(|s| s["mode"] == "autonomous" && s["velocity"] == 1.5),
        "{states:?}"
    );
}

/// A profile that secures the tug's command path (`[secoc]`), beside its DBC, and its key file
/// (readable by its owner only), in `dir`.
fn secured_profile(dir: &std::path::Path) -> (std::path::PathBuf, std::path::PathBuf) {
    use std::os::unix::fs::PermissionsExt;
    let tug = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../bywire-tug");
    std::fs::create_dir_all(dir).unwrap();
    std::fs::copy(
        tug.join("dbc/reference-tug.dbc"),
        dir.join("reference-tug.dbc"),
    )
    .unwrap();
    let profile = std::fs::read_to_string(tug.join("profiles/reference-tug.toml")).unwrap()
        + "\n[secoc]\nmessages = [\"AdsToVehicle_Control\", \"EmergencyBrake\", \"VehicleToAds_State\", \"VehicleToAds_Sensors\", \"VehicleToAds_WheelAngles\"]\nfv_length = 64\nfv_tx_length = 8\nmac_tx_length = 24\nkey_id = 1\nsync_id = 0x0F0\n";
    let profile_path = dir.join("secured.toml");
    std::fs::write(&profile_path, profile).unwrap();
    let key_path = dir.join("keys");
    std::fs::write(&key_path, "1 2b7e151628aed2a6abf7158809cf4f3c\n").unwrap();
    std::fs::set_permissions(&key_path, std::fs::Permissions::from_mode(0o600)).unwrap();
    (profile_path, key_path)
}

#[test]
fn a_secured_profile_drives_with_its_key_keeps_its_freshness_and_is_refused_without() {
    let dir = Scratch::new("bridge-secoc");
    let (profile, keys) = secured_profile(&dir);
    let freshness = dir.join("ads.freshness");
    let (profile, keys) = (profile.to_str().unwrap(), keys.to_str().unwrap());
    // Without its key every command that speaks it refuses to start.
    let mut refusing = vec![vec!["bridge", "--profile", profile, "virtual:x"]];
    refusing.push(vec!["vehicle", "--profile", profile, "virtual:x"]);
    #[cfg(feature = "ros2")]
    refusing.push(vec!["ros2", "vehicle", "--profile", profile, "virtual:x"]);
    for args in refusing {
        let (code, _, err) = common::bywire(&args, "");
        assert_eq!(code, 1, "{args:?}");
        assert!(
            err.contains("secoc: the profile secures its messages"),
            "{args:?}: {err}"
        );
    }
    // A key file for a profile that secures nothing is refused too.
    let (code, _, err) = common::bywire(
        &[
            "bridge",
            "--profile",
            "reference-tug",
            "virtual:x",
            "--key-file",
            keys,
        ],
        "",
    );
    assert_eq!(code, 1);
    assert!(err.contains("the profile declares no [secoc]"), "{err}");
    let fresh = freshness.to_str().unwrap();
    let states = drive_until(
        &[
            "bridge",
            "--profile",
            profile,
            "sim:bridge-secoc@500000/2000000",
            "--with-vehicle",
            "--rate",
            "20",
            "--key-file",
            keys,
            "--freshness-file",
            fresh,
        ],
        r#"{"velocity": 1.5, "gear": "drive", "mode": "autonomous"}"#,
        |s| s["mode"] == "autonomous" && s["velocity"] == 1.5,
    );
    // Every command authenticated by the vehicle (else it never engages), every state frame by
    // the ADS side (else no feedback).
    assert!(
        states
            .iter()
            .any(|s| s["mode"] == "autonomous" && s["velocity"] == 1.5),
        "never drove: {states:?}"
    );
    // The ADS side's verifications are in its state lines: state frames accepted, none refused
    // (an unsecured profile says null).
    let secoc = &states.last().unwrap()["secoc"];
    assert!(secoc["accepted"].as_u64().unwrap() > 20, "{secoc}");
    assert_eq!(secoc["rejected"], 0, "{secoc}");
    // At least 2.5 s of commands at 50 Hz, reserved ahead in the store.
    let kept: u64 = std::fs::read_to_string(&freshness)
        .unwrap()
        .trim()
        .parse()
        .unwrap();
    assert!(kept > 100, "{kept}");
}

/// What a driving bridge is made to do once the vehicle drives.
enum Then {
    /// Sent a signal (by `kill -SIGNAL`), its input still flowing.
    Signal(&'static str),
    /// Given this line, then driven on for two seconds.
    Line(&'static str),
}

/// The reference tug driven at 1.5 m/s by a bridge with `--estop-on-eof` until it drives,
/// then `then`, the drive lines flowing on until the bridge ends (15 s at most).
fn drive_then(bus: &str, then: Then) -> Run {
    let args = [
        "bridge",
        "--profile",
        "reference-tug",
        bus,
        "--with-vehicle",
        "--estop-on-eof",
        "--rate",
        "20",
    ];
    let mut bridge = Started::new(&args, |s| s["mode"] == "autonomous" && s["velocity"] == 1.5);
    let drive = "{\"velocity\": 1.5, \"gear\": \"drive\", \"mode\": \"autonomous\"}\n";
    let deadline = Instant::now() + Duration::from_secs(20);
    let mut k = 0usize;
    while !bridge.seen.load(Ordering::Relaxed) && Instant::now() < deadline {
        let line = if k > 0 && k.is_multiple_of(20) {
            format!("{ENGAGE}\n")
        } else {
            drive.to_string()
        };
        bridge.stdin.write_all(line.as_bytes()).unwrap();
        std::thread::sleep(Duration::from_millis(25));
        k += 1;
    }
    assert!(
        bridge.seen.load(Ordering::Relaxed),
        "the vehicle never drove"
    );
    let mut until = Instant::now() + Duration::from_secs(15);
    match then {
        Then::Signal(signal) => {
            let killed = Command::new("kill")
                .arg(format!("-{signal}"))
                .arg(bridge.child.id().to_string())
                .status()
                .unwrap();
            assert!(killed.success());
        }
        Then::Line(line) => {
            bridge
                .stdin
                .write_all(format!("{line}\n").as_bytes())
                .unwrap();
            until = Instant::now() + Duration::from_secs(2);
        }
    }
    // Commands to drive on keep coming: none may override the stop.
    while Instant::now() < until && bridge.stdin.write_all(drive.as_bytes()).is_ok() {
        std::thread::sleep(Duration::from_millis(25));
    }
    bridge.finish()
}

/// The lines from the first event of `kind` on.
fn from_event<'a>(run: &'a Run, kind: &str) -> &'a [Value] {
    let at = run.lines.iter().position(|l| l["event"] == kind);
    &run.lines[at.unwrap_or_else(|| panic!("no {kind} event: {:?}", run.lines))..]
}

/// SIGINT, SIGTERM (as systemd stops a service) and SIGHUP end the bridge as the end of input
/// does with --estop-on-eof: the braking second, the vehicle stopped, and no drive line taken
/// meanwhile though they keep coming. (Before, a signal ended the bridge at once, the last
/// frame on the bus commanding 1.5 m/s.)
#[test]
fn a_signal_ends_the_bridge_in_the_safe_stop() {
    for (signal, bus) in [
        ("INT", "sim:sig-int@500000"),
        ("TERM", "sim:sig-term@500000"),
        ("HUP", "sim:sig-hup@500000"),
    ] {
        let run = drive_then(bus, Then::Signal(signal));
        let after = from_event(&run, "end_of_input");
        assert!(
            after[0]["detail"]
                .as_str()
                .unwrap()
                .starts_with("a signal (SIGINT, SIGTERM or SIGHUP): braking for 1 s"),
            "{:?}",
            after[0]
        );
        assert!(
            after.iter().any(|l| l["event"] == "ignored"),
            "SIG{signal}: no drive line was refused while braking"
        );
        let states: Vec<&Value> = after.iter().filter(|l| l.get("mode").is_some()).collect();
        assert_eq!(
            states.last().unwrap()["velocity"],
            0.0,
            "SIG{signal}: {states:?}"
        );
    }
}

/// An emergency brake beyond the vehicle's deceleration is braking as hard as it can: taken at
/// the profile's 4 m/s² with a warning, and the vehicle stops (it was refused, and the tug drove
/// on). A setpoint refused on the same line does not cancel the brake.
#[test]
fn an_emergency_brake_beyond_the_vehicle_is_its_hardest() {
    let run = drive_then(
        "sim:ebrake-hard@500000",
        Then::Line(r#"{"emergency_brake": 9.81, "velocity": 99}"#),
    );
    let after = from_event(&run, "saturated");
    assert!(
        after[0]["detail"].as_str().unwrap().contains(
            "emergency_brake 9.81: beyond this vehicle's 4 m/s², braking as hard as it can"
        ),
        "{:?}",
        after[0]
    );
    assert!(after
        .iter()
        .any(|l| l["event"] == "emergency_brake" && l["detail"] == "4 m/s²"));
    assert!(after
        .iter()
        .any(|l| l["event"] == "bad_command"
            && l["detail"].as_str().unwrap().contains("velocity 99")));
    assert!(
        run.stderr.contains("braking as hard as it can"),
        "{}",
        run.stderr
    );
    let states: Vec<&Value> = after.iter().filter(|l| l.get("mode").is_some()).collect();
    assert!(
        states.iter().any(|s| s["velocity"] == 0.0),
        "never stopped: {states:?}"
    );
    // Zero is no deceleration: refused with what is wanted, not "not within 0–4".
    let (code, out, err) = common::bywire(
        &[
            "bridge",
            "--profile",
            "reference-tug",
            "virtual:ebrake-zero",
        ],
        "{\"emergency_brake\": 0}\n",
    );
    assert_eq!(code, 0, "{err}");
    assert!(
        err.contains("emergency_brake 0: a deceleration above 0 m/s² is needed"),
        "{err}"
    );
    assert!(!out.contains("\"event\":\"emergency_brake\""), "{out}");
}

/// A fail-operational vehicle (the redundant tug's profile, simulated) reports its
/// degradation level, and each state line shows it.
#[test]
fn bridge_shows_a_fail_operational_vehicles_degradation_level() {
    let drive = r#"{"velocity": 1.0, "gear": "drive", "mode": "autonomous"}"#;
    let states = drive_until(
        &[
            "bridge",
            "--profile",
            "reference-tug-redundant",
            "sim:bridge-redundant@500000",
            "--with-vehicle",
            "--rate",
            "20",
        ],
        drive,
        |s| s["degradation"]["level"] == "nominal",
    );
    let last = states.last().unwrap();
    assert_eq!(last["degradation"]["level"], "nominal", "{last}");
    assert!(last["degradation"]["reason"].is_null(), "{last}");
}
