//! python `canopen` 2.4 as the independent peer, over a socketcand server on a virtual bus
//! (the server runs in this process; python-can's socketcand interface connects to it):
//! - as master it reads and writes our drive's objects by expedited, segmented and block SDO,
//!   gets our abort codes, sets NMT states, receives our heartbeats and TPDOs, and walks our
//!   CiA 402 drive to Operation enabled with its `BaseNode402`;
//! - as slave (its `LocalNode`) it is read and written by our SDO client and commanded by our
//!   NMT master, whose heartbeat consumer follows its states.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use std::io::{BufRead, BufReader, Write};
use std::net::TcpListener;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use bywire_bus::socketcand::{self, Server};
use bywire_bus::{open, runner, BusError};
use bywire_canopen::cia402::{self, Drive};
use bywire_canopen::device::Device;
use bywire_canopen::eds::{self, DeviceInfo};
use bywire_canopen::master::{Master, MasterEvent};
use bywire_canopen::nmt::{HeartbeatEvent, NmtCommand, NmtState};
use bywire_canopen::od::{Access, DataType, Entry};
use bywire_canopen::roboteq;
use bywire_canopen::sdo::{SdoError, TransferMode};
use bywire_canopen::{Abort, Node, Port};
use bywire_core::frame::Frame;
use bywire_core::time::Timestamp;

/// A socketcand server for `virtual:NAME` on a free port (it stops when dropped).
fn server(name: &str) -> Server {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let spec = format!("virtual:{name}");
    let open_bus =
        Arc::new(move |_name: &str| open(&spec).map_err(|e| BusError::Unsupported(e.to_string())));
    Server::start(listener, socketcand::Config::default(), open_bus).unwrap()
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("bywire-canopen-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Run `script` with python3; `PORT`, `CHANNEL` and `EDS` are given in its environment.
fn python(script: &str, port: u16, channel: &str, eds: &std::path::Path) -> Child {
    Command::new("python3")
        .arg("-c")
        .arg(script)
        .env("PORT", port.to_string())
        .env("CHANNEL", channel)
        .env("EDS", eds)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("python3 with canopen 2.4 (scripts/install-test-deps.sh)")
}

fn finish(child: Child) -> Vec<String> {
    let output = child.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&output.stdout).to_string();
    assert!(
        output.status.success(),
        "python failed:\n{stdout}\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    stdout.lines().map(str::to_string).collect()
}

const PREAMBLE: &str = r#"
import os, sys, time, canopen, logging
network = canopen.Network()
network.connect(interface="socketcand", host="127.0.0.1", port=int(os.environ["PORT"]), channel=os.environ["CHANNEL"])
def say(*parts):
    print(*parts, flush=True)
"#;

/// Our drive's dictionary plus a writable domain for long transfers.
fn drive_dictionary(node: u8) -> bywire_canopen::od::ObjectDictionary {
    let mut od = cia402::drive_dictionary(node);
    od.add_var(
        0x2F00,
        Entry::new(0, "Scratch", DataType::Domain, Access::ReadWrite).with_default(&[0; 600]),
    );
    od.add_var(
        0x2F01,
        Entry::new(0, "Label", DataType::VisibleString, Access::ReadWrite).with_default(b"tug"),
    );
    od
}

/// Run our drive on `virtual:NAME` while python runs `script`; the drive afterwards.
fn with_our_drive(name: &str, script: &str) -> (Vec<String>, Device<Drive>) {
    const NODE: u8 = 2;
    with_our_device(name, drive_dictionary(NODE), Drive::new(), NODE, script)
}

/// Run a device of ours (`od` and `app`, at `node`) on `virtual:NAME` while python runs
/// `script` with the device's EDS; the device afterwards.
fn with_our_device<A: bywire_canopen::device::Application + Send + 'static>(
    name: &str,
    od: bywire_canopen::od::ObjectDictionary,
    app: A,
    node: u8,
    script: &str,
) -> (Vec<String>, Device<A>) {
    let served = server(name);
    let port = served.local_addr().port();
    let dir = scratch(name);
    let eds_path = dir.join("device.eds");
    let info = DeviceInfo {
        vendor_name: "bywire".into(),
        product_name: name.into(),
        bitrates: vec![1000],
        ..DeviceInfo::default()
    };
    std::fs::write(&eds_path, eds::write(&od, &info, Some(node))).unwrap();
    let bus = open(&format!("virtual:{name}")).unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    let device = Device::new(node, od, app);
    let runner_stop = Arc::clone(&stop);
    let handle = std::thread::spawn(move || runner::run(bus, device, &runner_stop).unwrap());
    let lines = finish(python(
        &format!("{PREAMBLE}{script}"),
        port,
        name,
        &eds_path,
    ));
    stop.store(true, Ordering::Relaxed);
    let device = handle.join().unwrap();
    (lines, device)
}

fn value<'a>(lines: &'a [String], key: &str) -> &'a str {
    lines
        .iter()
        .find_map(|line| {
            line.strip_prefix(key)
                .and_then(|rest| rest.strip_prefix(' '))
        })
        .unwrap_or_else(|| panic!("no '{key}' in {lines:#?}"))
}

#[test]
fn python_canopen_as_master_reads_and_writes_our_drive() {
    let script = r#"
node = network.add_node(2, os.environ["EDS"])
time.sleep(0.3)
say("device_type", hex(int.from_bytes(node.sdo.upload(0x1000, 0), "little")))
say("name", node.sdo["Manufacturer device name"].raw)
say("vendor", hex(node.sdo[0x1018][1].raw))
node.sdo[0x6081].raw = 1234
say("profile_velocity", node.sdo[0x6081].raw)
node.sdo.download(0x2F01, 0, b"a longer label than four bytes")
say("label", node.sdo.upload(0x2F01, 0).decode())
data = bytes((i * 7) % 256 for i in range(600))
with node.sdo.open(0x2F00, 0, "wb", block_transfer=True, size=len(data)) as f:
    f.write(data)
with node.sdo.open(0x2F00, 0, "rb", block_transfer=True) as f:
    back = f.read()
say("block_roundtrip", back == data, len(back))
seg = bytes(range(100))
node.sdo.download(0x2F00, 0, seg, force_segment=True)
say("segmented_roundtrip", node.sdo.upload(0x2F00, 0) == seg)
for (index, sub, payload) in [(0x1000, 0, b"\x01\x02\x03\x04"), (0x5555, 0, b"\x01"), (0x6040, 0, b"\x01\x02\x03"), (0x1018, 9, b"\x01")]:
    try:
        node.sdo.download(index, sub, payload)
        say("abort", hex(index), "none")
    except canopen.SdoAbortedError as e:
        say("abort", hex(index), hex(e.code))
try:
    node.sdo.upload(0x1018, 9)
except canopen.SdoAbortedError as e:
    say("abort_upload", hex(e.code))
node.nmt.state = "OPERATIONAL"
node.nmt.wait_for_heartbeat(timeout=1)
node.nmt.wait_for_heartbeat(timeout=1)
say("nmt_operational", node.nmt.state)
node.tpdo.read()
say("tpdo1_cob", hex(node.tpdo[1].cob_id), node.tpdo[1].trans_type, node.tpdo[1].event_timer)
node.tpdo[1].wait_for_reception(timeout=1)
say("tpdo1_statusword", hex(node.tpdo[1]["Statusword"].raw))
node.nmt.state = "STOPPED"
node.nmt.wait_for_heartbeat(timeout=1)
node.nmt.wait_for_heartbeat(timeout=1)
say("nmt_stopped", node.nmt.state)
try:
    node.sdo.upload(0x1000, 0)
    say("sdo_in_stopped", "answered")
except canopen.SdoCommunicationError:
    say("sdo_in_stopped", "silent")
node.nmt.state = "PRE-OPERATIONAL"
# A heartbeat sent just before the command may still be on its way: take the next one too.
node.nmt.wait_for_heartbeat(timeout=1)
node.nmt.wait_for_heartbeat(timeout=1)
say("nmt_preop", node.nmt.state)
network.disconnect()
"#;
    let (lines, device) = with_our_drive("py-master", script);
    assert_eq!(value(&lines, "device_type"), "0x20192");
    assert_eq!(value(&lines, "name"), "bywire drive");
    assert_eq!(value(&lines, "vendor"), "0xb1e");
    assert_eq!(value(&lines, "profile_velocity"), "1234");
    assert_eq!(device.od().get_unsigned(0x6081, 0), Some(1234));
    assert_eq!(value(&lines, "label"), "a longer label than four bytes");
    assert_eq!(value(&lines, "block_roundtrip"), "True 600");
    assert_eq!(value(&lines, "segmented_roundtrip"), "True");
    let aborts: Vec<&String> = lines.iter().filter(|l| l.starts_with("abort ")).collect();
    assert_eq!(
        aborts,
        [
            "abort 0x1000 0x6010002",
            "abort 0x5555 0x6020000",
            "abort 0x6040 0x6070012",
            "abort 0x1018 0x6090011"
        ]
    );
    assert_eq!(value(&lines, "abort_upload"), "0x6090011");
    assert_eq!(value(&lines, "nmt_operational"), "OPERATIONAL");
    assert_eq!(value(&lines, "tpdo1_cob"), "0x182 255 100");
    assert_eq!(
        value(&lines, "tpdo1_statusword"),
        "0x240",
        "switch on disabled, remote"
    );
    assert_eq!(value(&lines, "nmt_stopped"), "STOPPED");
    assert_eq!(value(&lines, "sdo_in_stopped"), "silent");
    assert_eq!(value(&lines, "nmt_preop"), "PRE-OPERATIONAL");
    assert_eq!(device.state(), NmtState::PreOperational);
}

#[test]
fn python_canopen_base_node_402_walks_our_drive_to_operation_enabled() {
    let script = r#"
from canopen.profiles.p402 import BaseNode402
node = BaseNode402(2, os.environ["EDS"])
network.add_node(node)
time.sleep(0.3)
node.nmt.state = "OPERATIONAL"
node.nmt.wait_for_heartbeat(timeout=1)
node.setup_402_state_machine()
# RPDO1 carries the mode with the controlword: python must set it (it sends zeros otherwise),
# and confirms it from TPDO1's modes display.
node.op_mode = "PROFILED VELOCITY"
say("op_mode", node.op_mode)
node.state = "OPERATION ENABLED"
say("state", node.state)
node.sdo[0x60FF].raw = 800
deadline = time.time() + 2
while time.time() < deadline and node.sdo[0x606C].raw != 800:
    time.sleep(0.05)
say("velocity", node.sdo[0x606C].raw)
node.state = "SWITCH ON DISABLED"
say("state_after", node.state)
network.disconnect()
"#;
    let (lines, device) = with_our_drive("py-402", script);
    assert_eq!(value(&lines, "op_mode"), "PROFILED VELOCITY");
    assert_eq!(value(&lines, "state"), "OPERATION ENABLED");
    assert_eq!(value(&lines, "velocity"), "800");
    assert_eq!(value(&lines, "state_after"), "SWITCH ON DISABLED");
    assert_eq!(device.app().state(), cia402::State::SwitchOnDisabled);
}

/// python-canopen's `BaseNode402` drives the simulated Roboteq through its CiA 402 face, as it
/// would the real controller: device type, the state machine to Operation enabled, a speed in
/// RPM and a move in encoder counts; then Roboteq's own motor command drives it again.
#[test]
fn python_canopen_base_node_402_drives_the_roboteq_through_its_cia402_face() {
    let script = r#"
from canopen.profiles.p402 import BaseNode402
node = BaseNode402(1, os.environ["EDS"])
network.add_node(node)
time.sleep(0.3)
say("device_type", hex(node.sdo[0x1000].raw))
node.nmt.state = "OPERATIONAL"
node.nmt.wait_for_heartbeat(timeout=1)
node.setup_402_state_machine(read_pdos=False)
node.op_mode = "PROFILED VELOCITY"
node.state = "OPERATION ENABLED"
say("state", node.state)
node.sdo[0x60FF].raw = 1200
deadline = time.time() + 2
while time.time() < deadline and abs(node.sdo[0x606C].raw - 1200) > 2:
    time.sleep(0.05)
say("velocity", node.sdo[0x606C].raw)
node.sdo[0x60FF].raw = 0
time.sleep(0.5)
node.op_mode = "PROFILED POSITION"
node.sdo[0x6081].raw = 1000
start = node.sdo[0x6064].raw
node.sdo[0x607A].raw = start + 8192
node.controlword = 0x1F
deadline = time.time() + 3
while time.time() < deadline and not (node.statusword & 0x0400 and abs(node.sdo[0x6064].raw - start - 8192) <= 10):
    time.sleep(0.05)
say("moved", node.sdo[0x6064].raw - start)
node.state = "SWITCH ON DISABLED"
say("state_after", node.state)
node.sdo[0x2000][1].raw = 500
# Five time constants, and well inside the controller's 1 s command watchdog.
time.sleep(0.8)
say("roboteq_speed", node.sdo[0x2103][1].raw)
network.disconnect()
"#;
    let (lines, device) = with_our_device(
        "py-roboteq-402",
        roboteq::dictionary(1, 2),
        roboteq::Mdc1460::default(),
        1,
        script,
    );
    assert_eq!(value(&lines, "device_type"), "0x20192");
    assert_eq!(value(&lines, "state"), "OPERATION ENABLED");
    let velocity: i64 = value(&lines, "velocity").parse().unwrap();
    assert!((velocity - 1200).abs() <= 2, "{velocity}");
    let moved: i64 = value(&lines, "moved").parse().unwrap();
    assert!((moved - 8192).abs() <= 10, "{moved}");
    assert_eq!(value(&lines, "state_after"), "SWITCH ON DISABLED");
    let speed: i64 = value(&lines, "roboteq_speed").parse().unwrap();
    assert!((speed - 1500).abs() <= 30, "50 % of 3000 RPM: {speed}");
    assert_eq!(
        device.app().drive().state(),
        cia402::State::SwitchOnDisabled
    );
}

/// Something done to the master at a time.
type Action = (Timestamp, Box<dyn FnMut(&mut Master) + Send>);

/// A node that runs `actions` at their times (from the runner's start) around a master.
struct Scripted {
    master: Master,
    actions: Vec<Action>,
}

impl Node for Scripted {
    fn on_frame(&mut self, now: Timestamp, _port: Port, frame: &Frame) {
        self.master.on_frame(now, Port::MAIN, frame);
    }
    fn poll(&mut self, now: Timestamp, out: &mut dyn FnMut(Port, Frame)) {
        for (at, action) in &mut self.actions {
            if *at <= now {
                action(&mut self.master);
                *at = Timestamp::from_nanos(u64::MAX);
            }
        }
        self.master
            .poll(now, &mut |_, frame| out(Port::MAIN, frame));
    }
    fn next_deadline(&self) -> Option<Timestamp> {
        let next_action = self.actions.iter().map(|(at, _)| *at).min();
        [self.master.next_deadline(), next_action]
            .into_iter()
            .flatten()
            .min()
    }
}

#[test]
fn our_master_reads_writes_and_commands_a_python_local_node() {
    const NODE: u8 = 5;
    let name = "py-slave";
    let served = server(name);
    let port = served.local_addr().port();
    let dir = scratch(name);
    // The slave's dictionary: ours, written as EDS, read by python-canopen.
    let mut od = bywire_canopen::od::ObjectDictionary::new();
    cia402::communication_objects(
        &mut od,
        NODE,
        0x0001_0191,
        "python slave",
        [0x1234, 0x5678, 1, 42],
    );
    od.add_var(
        0x2000,
        Entry::new(0, "Setting", DataType::U32, Access::ReadWrite).with_int(7),
    );
    od.add_var(
        0x2001,
        Entry::new(0, "Message", DataType::VisibleString, Access::ReadWrite).with_default(b"hello"),
    );
    let eds_path = dir.join("slave.eds");
    std::fs::write(
        &eds_path,
        eds::write(&od, &DeviceInfo::default(), Some(NODE)),
    )
    .unwrap();
    let script = format!(
        r#"{PREAMBLE}
node = network.create_node({NODE}, os.environ["EDS"])
node.nmt.state = "PRE-OPERATIONAL"
node.nmt.start_heartbeat(50)
say("ready")
time.sleep(4)
say("setting", node.sdo[0x2000].raw)
say("message", node.sdo[0x2001].raw)
say("state", node.nmt.state)
network.disconnect()
"#
    );
    let mut child = python(&script, port, name, &eds_path);
    let mut stdout = BufReader::new(child.stdout.take().unwrap());
    let mut ready = String::new();
    stdout.read_line(&mut ready).unwrap();
    assert_eq!(ready.trim(), "ready");
    let long_text = b"a message longer than seven bytes, segmented".to_vec();
    let mut master = Master::new(1, Duration::ZERO, Duration::from_millis(10));
    master.monitor(NODE, Duration::from_millis(200));
    let sdo = master.sdo();
    sdo.upload(NODE, 0x1000, 0, TransferMode::Auto).unwrap();
    sdo.upload(NODE, 0x1008, 0, TransferMode::Auto).unwrap();
    sdo.download(
        NODE,
        0x2000,
        0,
        &0xDEAD_BEEFu32.to_le_bytes(),
        TransferMode::Auto,
    )
    .unwrap();
    sdo.upload(NODE, 0x2000, 0, TransferMode::Segmented)
        .unwrap();
    sdo.download(NODE, 0x2001, 0, &long_text, TransferMode::Auto)
        .unwrap();
    sdo.upload(NODE, 0x2001, 0, TransferMode::Block).unwrap();
    sdo.download(NODE, 0x2001, 0, b"block", TransferMode::Block)
        .unwrap();
    sdo.upload(NODE, 0x7777, 0, TransferMode::Auto).unwrap();
    let scripted = Scripted {
        master,
        actions: vec![
            (
                Timestamp::from_millis(1_000),
                Box::new(|m: &mut Master| m.nmt(NmtCommand::Start, NODE)),
            ),
            (
                Timestamp::from_millis(1_500),
                Box::new(|m: &mut Master| m.nmt(NmtCommand::Stop, NODE)),
            ),
            (
                Timestamp::from_millis(2_000),
                Box::new(|m: &mut Master| m.nmt(NmtCommand::EnterPreOperational, NODE)),
            ),
            (
                Timestamp::from_millis(2_500),
                Box::new(|m: &mut Master| m.nmt(NmtCommand::Start, 0)),
            ),
        ],
    };
    let bus = open(&format!("virtual:{name}")).unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    let runner_stop = Arc::clone(&stop);
    let handle = std::thread::spawn(move || runner::run(bus, scripted, &runner_stop).unwrap());
    std::thread::sleep(Duration::from_millis(3_200));
    stop.store(true, Ordering::Relaxed);
    let mut master = handle.join().unwrap().master;
    let mut rest = String::new();
    std::io::Read::read_to_string(&mut stdout, &mut rest).unwrap();
    let status = child.wait().unwrap();
    let lines: Vec<String> = rest.lines().map(str::to_string).collect();
    assert!(status.success(), "{lines:?}");
    let outcomes: Vec<_> = std::iter::from_fn(|| master.take_sdo_outcome())
        .map(|o| o.result)
        .collect();
    assert_eq!(outcomes[0], Ok(0x0001_0191u32.to_le_bytes().to_vec()));
    assert_eq!(outcomes[1], Ok(b"python slave".to_vec()));
    assert_eq!(outcomes[2], Ok(vec![]));
    assert_eq!(outcomes[3], Ok(0xDEAD_BEEFu32.to_le_bytes().to_vec()));
    assert_eq!(outcomes[4], Ok(vec![]));
    assert_eq!(
        outcomes[5],
        Ok(long_text.clone()),
        "python switches a block upload to a normal one"
    );
    assert_eq!(
        outcomes[6],
        Err(SdoError::Aborted(Abort::InvalidCommand)),
        "python has no block download"
    );
    assert_eq!(outcomes[7], Err(SdoError::Aborted(Abort::NoObject)));
    assert_eq!(value(&lines, "setting"), "3735928559");
    assert_eq!(
        value(&lines, "message"),
        String::from_utf8(long_text).unwrap()
    );
    assert_eq!(value(&lines, "state"), "OPERATIONAL");
    let states: Vec<NmtState> = std::iter::from_fn(|| master.next_event())
        .filter_map(|e| match e {
            MasterEvent::Heartbeat(HeartbeatEvent::StateChanged { node: NODE, state }) => {
                Some(state)
            }
            _ => None,
        })
        .collect();
    assert_eq!(
        states,
        [
            NmtState::PreOperational,
            NmtState::Operational,
            NmtState::Stopped,
            NmtState::PreOperational,
            NmtState::Operational
        ]
    );
    let _ = std::io::stdout().flush();
}
