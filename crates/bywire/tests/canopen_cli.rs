//! `bywire canopen` end to end: `bywire serve` shares a virtual bus over socketcand;
//! `bywire canopen node` runs devices on it; `scan`, `sdo` and `nmt` talk to them; python
//! `canopen` 2.4 is the independent peer on both sides (master of our EDS-described device,
//! and a LocalNode our commands scan, read, write and command).
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

mod common;

use common::Scratch;

const BIN: &str = env!("CARGO_BIN_EXE_bywire");

/// A child killed when the test ends, pass or fail.
struct Running(Child);

impl Drop for Running {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// `bywire serve virtual:NAME` on a free port; the bus spec clients use.
fn serve(name: &str) -> (Running, String) {
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let mut child = Command::new(BIN)
        .args([
            "serve",
            &format!("virtual:{name}"),
            "--listen",
            &format!("127.0.0.1:{port}"),
        ])
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut first = String::new();
    BufReader::new(child.stdout.as_mut().unwrap())
        .read_line(&mut first)
        .unwrap();
    assert!(first.starts_with("serving"), "{first}");
    (
        Running(child),
        format!("socketcand:127.0.0.1:{port}/{name}"),
    )
}

/// `bywire canopen node BUS ...`, once it has said it runs.
fn device(bus: &str, args: &[&str]) -> Running {
    let mut child = Command::new(BIN)
        .args(["canopen", "node", bus])
        .args(args)
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut first = String::new();
    BufReader::new(child.stdout.as_mut().unwrap())
        .read_line(&mut first)
        .unwrap();
    assert!(first.starts_with("node "), "{first}");
    // Let its boot-up and first heartbeat go out.
    std::thread::sleep(Duration::from_millis(300));
    Running(child)
}

fn bywire(args: &[&str]) -> (bool, String, String) {
    let output = Command::new(BIN).args(args).output().unwrap();
    (
        output.status.success(),
        String::from_utf8_lossy(&output.stdout).into_owned(),
        String::from_utf8_lossy(&output.stderr).into_owned(),
    )
}

fn ok(args: &[&str]) -> String {
    let (success, stdout, stderr) = bywire(args);
    assert!(success, "bywire {args:?} failed: {stderr}");
    stdout
}

#[test]
fn scan_sdo_and_nmt_against_our_devices() {
    let (_server, bus) = serve("co-cli");
    let _drive = device(&bus, &["--node", "3", "--profile", "cia402"]);
    let _roboteq = device(
        &bus,
        &["--node", "1", "--profile", "roboteq", "--autostart"],
    );
    let scan = ok(&["canopen", "scan", &bus]);
    let rows: Vec<&str> = scan.lines().skip(1).collect();
    assert_eq!(rows.len(), 2, "{scan}");
    assert!(
        rows[0].starts_with("   1  OPERATIONAL      0x00020192   0x00000358  0x00001460"),
        "{scan}"
    );
    assert!(rows[0].ends_with("MDC1460"), "{scan}");
    assert!(
        rows[1].starts_with("   3  PRE-OPERATIONAL  0x00020192   0x00000B1E  0x00000402"),
        "{scan}"
    );
    assert!(rows[1].ends_with("bywire drive"), "{scan}");
    assert_eq!(
        ok(&["canopen", "sdo", &bus, "3", "read", "0x1008", "--type", "str"]),
        "bywire drive\n"
    );
    assert_eq!(
        ok(&["canopen", "sdo", &bus, "3", "read", "1000:0"]),
        "92 01 02 00\n"
    );
    ok(&[
        "canopen", "sdo", &bus, "3", "write", "0x6081", "1500", "--type", "u32",
    ]);
    for mode in ["auto", "segmented", "block"] {
        assert_eq!(
            ok(
                &[
                    "canopen", "sdo", &bus, "3", "read", "0x6081:0", "--type", "u32", "--mode",
                    mode
                ]
            ),
            "1500\n",
            "{mode}"
        );
    }
    // The roboteq takes a negative motor command (two's complement) and reports it back.
    ok(&[
        "canopen", "sdo", &bus, "1", "write", "0x2000:1", "-700", "--type", "i32",
    ]);
    std::thread::sleep(Duration::from_millis(200));
    assert_eq!(
        ok(&["canopen", "sdo", &bus, "1", "read", "0x2101:1", "--type", "i16"]),
        "-700\n"
    );
    // Refusals carry the abort code.
    let (success, _, stderr) = bywire(&[
        "canopen", "sdo", &bus, "3", "write", "0x1000", "1", "--type", "u32",
    ]);
    assert!(!success);
    assert!(stderr.contains("node 3, 0x1000:00: the server aborted: 0x06010002 (attempt to write a read-only object)"), "{stderr}");
    let (success, _, stderr) = bywire(&[
        "canopen", "sdo", &bus, "1", "write", "0x2000:1", "1001", "--type", "i32",
    ]);
    assert!(!success && stderr.contains("0x06090031"), "{stderr}");
    let (success, _, stderr) = bywire(&[
        "canopen",
        "sdo",
        &bus,
        "9",
        "read",
        "0x1000",
        "--timeout",
        "200",
    ]);
    assert!(
        !success && stderr.contains("node 9, 0x1000:00: no response within the timeout"),
        "{stderr}"
    );
    // NMT, confirmed by the node's heartbeat.
    assert_eq!(
        ok(&["canopen", "nmt", &bus, "3", "start"]),
        "node 3: OPERATIONAL\n"
    );
    assert_eq!(
        ok(&["canopen", "nmt", &bus, "3", "stop"]),
        "node 3: STOPPED\n"
    );
    assert_eq!(
        ok(&["canopen", "nmt", &bus, "3", "reset"]),
        "node 3: boot-up, PRE-OPERATIONAL\n"
    );
    assert_eq!(
        ok(&["canopen", "sdo", &bus, "3", "read", "0x6081", "--type", "u32"]),
        "2000\n",
        "reset node restored the default"
    );
    let (success, _, stderr) = bywire(&["canopen", "nmt", &bus, "3", "jump"]);
    assert!(
        !success && stderr.contains("'jump': not an NMT command"),
        "{stderr}"
    );
}

#[test]
fn python_canopen_masters_an_eds_described_device_and_answers_as_a_local_node() {
    let (_server, bus) = serve("co-py");
    let port = bus
        .split(':')
        .nth(2)
        .unwrap()
        .split('/')
        .next()
        .unwrap()
        .to_string();
    let dir = Scratch::new("canopen-cli");
    // An EDS-described device: the Roboteq dictionary written out, then served from the file.
    let eds = dir.join("roboteq.eds");
    drop(device(
        &bus,
        &[
            "--node",
            "9",
            "--profile",
            "roboteq",
            "--export-eds",
            eds.to_str().unwrap(),
            "--duration",
            "0.1",
        ],
    ));
    let _generic = device(&bus, &["--node", "4", "--eds", eds.to_str().unwrap()]);
    let script = format!(
        r#"
import canopen, time
network = canopen.Network()
network.connect(interface="socketcand", host="127.0.0.1", port={port}, channel="co-py")
node = network.add_node(4, r"{eds}")
time.sleep(0.2)
print("name", node.sdo[0x1008].raw)
node.sdo[0x2000][1].raw = -250
print("tpdo_cob", hex(node.sdo[0x1800][1].raw))
node.nmt.state = "OPERATIONAL"
node.nmt.wait_for_heartbeat(timeout=1)
print("state", node.nmt.state)
local = network.create_node(12, r"{eds}")
local.nmt.state = "PRE-OPERATIONAL"
local.nmt.start_heartbeat(50)
print("ready", flush=True)
time.sleep(3)
print("local_command", local.sdo[0x2000][2].raw)
print("local_state", local.nmt.state)
network.disconnect()
"#,
        eds = eds.display()
    );
    let mut python = Command::new("python3")
        .arg("-c")
        .arg(&script)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut reader = BufReader::new(python.stdout.take().unwrap());
    let mut lines = Vec::new();
    loop {
        let mut line = String::new();
        assert!(
            reader.read_line(&mut line).unwrap() > 0,
            "python ended early: {lines:?}"
        );
        if line.trim() == "ready" {
            break;
        }
        lines.push(line.trim().to_string());
    }
    assert_eq!(
        lines,
        ["name MDC1460", "tpdo_cob 0x184", "state OPERATIONAL"]
    );
    // python's LocalNode, found, read, written and commanded by our commands.
    let scan = ok(&["canopen", "scan", &bus]);
    assert!(
        scan.lines()
            .any(|row| row.starts_with("  12  PRE-OPERATIONAL") && row.ends_with("MDC1460")),
        "{scan}"
    );
    assert_eq!(
        ok(&[
            "canopen",
            "sdo",
            &bus,
            "12",
            "read",
            "0x1008",
            "--eds",
            eds.to_str().unwrap()
        ]),
        "MDC1460\n"
    );
    ok(&[
        "canopen",
        "sdo",
        &bus,
        "12",
        "write",
        "0x2000:2",
        "-1000",
        "--eds",
        eds.to_str().unwrap(),
    ]);
    assert_eq!(
        ok(&["canopen", "nmt", &bus, "12", "start"]),
        "node 12: OPERATIONAL\n"
    );
    let mut rest = String::new();
    std::io::Read::read_to_string(&mut reader, &mut rest).unwrap();
    let output = python.wait_with_output().unwrap();
    assert!(
        output.status.success(),
        "{rest}{}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert_eq!(rest, "local_command -1000\nlocal_state OPERATIONAL\n");
}

#[test]
fn eds_check_names_lines_and_fails_on_errors() {
    let dir = Scratch::new("canopen-eds");
    let path = dir.join("bad.eds");
    std::fs::write(&path, "[DeviceInfo]\nVendorName=Acme\nProductName=Box\n[1000]\nParameterName=Device type\nDataType=0x0007\nAccessType=ro\n[2000]\nParameterName=Broken\nDataType=0x0042\nAccessType=rw\n").unwrap();
    let (success, stdout, stderr) = bywire(&["canopen", "eds", path.to_str().unwrap()]);
    assert!(!success);
    assert!(stdout.contains("bad.eds: line 10: error: [2000]: DataType '0x0042' is not a CiA 301 basic type; object left out"), "{stdout}");
    assert!(
        stdout.contains("bad.eds: Acme Box: 1 objects, 1 entries, 0 RPDOs, 0 TPDOs"),
        "{stdout}"
    );
    assert!(stderr.contains("objects were left out"), "{stderr}");
    // A device is not started from a file the check refuses.
    let (success, _, stderr) = bywire(&[
        "canopen",
        "node",
        "virtual:eds-refused",
        "--node",
        "3",
        "--eds",
        path.to_str().unwrap(),
        "--duration",
        "0.5",
    ]);
    assert!(!success);
    assert!(stderr.contains("objects were left out"), "{stderr}");
    // Vendors' tools often write Latin-1: read, and said.
    let latin = dir.join("latin.eds");
    std::fs::write(&latin, b"[DeviceInfo]\nVendorName=M\xfcller Antriebe\nProductName=Motor 5\xb0\n[1000]\nParameterName=Device type\nDataType=0x0007\nAccessType=ro\n").unwrap();
    let (success, stdout, stderr) = bywire(&["canopen", "eds", latin.to_str().unwrap()]);
    assert!(success, "{stdout}{stderr}");
    assert!(
        stdout.contains("latin.eds: line 2: warning: not UTF-8: read as Windows-1252 (Latin-1)"),
        "{stdout}"
    );
    assert!(
        stdout.contains("latin.eds: Müller Antriebe Motor 5°: 1 objects"),
        "{stdout}"
    );
}
