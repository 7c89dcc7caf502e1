//! `bywire web` against real clients: its page in Debian's Chromium (driven by Playwright)
//! while python-can sends frames cantools encoded, and its Foxglove WebSocket side with
//! Foxglove's own client (`@foxglove/ws-protocol` in Node). Inside `lonet.sh` (multicast).
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

mod common;

use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};

use common::{inside_lonet, Scratch};

fn dbc() -> String {
    format!(
        "{}/../../examples/data/reference-tug.dbc",
        env!("CARGO_MANIFEST_DIR")
    )
}

/// Where the install script puts the Node packages (`@foxglove/ws-protocol`, `ws`).
fn node_modules() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../target/node/node_modules")
}

/// `bywire web ARGS` started, with the address it serves on (read from its first line: the
/// server is listening once it is printed).
struct Web {
    child: Child,
    address: String,
    /// The rest of what it says.
    lines: std::io::Lines<BufReader<std::process::ChildStdout>>,
}

impl Web {
    fn start(args: &[&str]) -> Web {
        let mut child = Command::new(env!("CARGO_BIN_EXE_bywire"))
            .arg("web")
            .args(args)
            .args(["--listen", "127.0.0.1:0"])
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .unwrap();
        let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
        let line = lines.next().unwrap().unwrap();
        let address = line
            .strip_prefix("the page on http://")
            .and_then(|rest| rest.split('/').next())
            .unwrap_or_else(|| panic!("no address in {line:?}"))
            .to_string();
        Web {
            child,
            address,
            lines,
        }
    }

    /// Stop it as Ctrl-C does: it must end cleanly.
    fn stop(mut self) {
        Command::new("kill")
            .args(["-INT", &self.child.id().to_string()])
            .status()
            .unwrap();
        let status = self.child.wait().unwrap();
        assert!(status.success(), "bywire web ended with {status}");
    }
}

impl Drop for Web {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// `bywire send ARGS`, which must succeed.
fn send(args: &[&str]) {
    let (code, _, err) = common::bywire(&[&["send"], args].concat(), "");
    assert_eq!(code, 0, "{err}");
}

/// `bywire dump -L BUS` into a file, until stopped.
fn dump_to(bus: &str, file: &std::path::Path) -> Child {
    Command::new(env!("CARGO_BIN_EXE_bywire"))
        .args(["dump", "-L", bus])
        .stdout(std::fs::File::create(file).unwrap())
        .spawn()
        .unwrap()
}

/// Wait (bounded) until `file` holds `count` lines containing `needle`.
fn wait_for_lines(file: &std::path::Path, needle: &str, count: usize) -> String {
    for _ in 0..200 {
        let text = std::fs::read_to_string(file).unwrap_or_default();
        if text.lines().filter(|l| l.contains(needle)).count() >= count {
            return text;
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    panic!(
        "{needle} never seen {count} times: {}",
        std::fs::read_to_string(file).unwrap_or_default()
    );
}

#[test]
fn the_page_shows_decodes_plots_and_sends_as_cantools_and_dump_agree() {
    if !inside_lonet("the_page_shows_decodes_plots_and_sends_as_cantools_and_dump_agree") {
        return;
    }
    let (group, port) = ("239.74.163.2", "43620");
    let bus = format!("udp:{group}:{port}");
    let scratch = Scratch::new("web-page");
    let shots = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../target/web-screenshots");
    std::fs::create_dir_all(&shots).unwrap();
    let dumped = scratch.join("dump.log");
    let mut dump = dump_to(&bus, &dumped);
    let web = Web::start(&[&bus, "--db", &dbc(), "--allow-send", "--bitrate", "500000"]);
    let out = Command::new("python3")
        .arg(format!("{}/web_page.py", common::oracles()))
        .args([
            &format!("http://{}/", web.address),
            group,
            port,
            &dbc(),
            shots.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    // What the transmit panel sent, as `bywire dump` saw it on the bus.
    let text = wait_for_lines(&dumped, " 100#", 1);
    let _ = dump.kill();
    let _ = dump.wait();
    web.stop();
    assert!(
        text.lines()
            .any(|l| l.ends_with(&format!("{bus} 123#DEADBEEF"))),
        "{text}"
    );
    let control = text
        .lines()
        .find(|l| l.contains(" 100#"))
        .unwrap()
        .rsplit('#')
        .next()
        .unwrap()
        .to_string();
    let decoded = Command::new("python3")
        .args([
            "-c",
            "import cantools, sys; db = cantools.database.load_file(sys.argv[1]); \
             m = db.get_message_by_name('AdsToVehicle_Control'); \
             d = m.decode(bytes.fromhex(sys.argv[2])); \
             print(d['VelocityCmd'], d['SteeringAngleCmd'], d['GearCmd'])",
            &dbc(),
            &control,
        ])
        .output()
        .unwrap();
    assert_eq!(
        String::from_utf8_lossy(&decoded.stdout).trim(),
        "1.5 -12.5 Drive",
        "{control}: {}",
        String::from_utf8_lossy(&decoded.stderr)
    );
}

/// Foxglove's own client (`@foxglove/ws-protocol` in Node) lists the channels, receives the
/// raw frames and a decoded message equal to what `bywire dump --dbc` prints of the same bus,
/// and publishes a raw frame and a message by its signals, which `bywire dump` sees.
#[test]
fn foxglove_clients_see_what_dump_prints_and_publish_frames() {
    if !inside_lonet("foxglove_clients_see_what_dump_prints_and_publish_frames") {
        return;
    }
    let bus = "udp:239.74.163.2:43621";
    let scratch = Scratch::new("web-foxglove");
    let dumped = scratch.join("dump.txt");
    // Foxglove on a port of its own as well: the client connects there.
    let mut web = Web::start(&[
        &format!("tug={bus}"),
        "--db",
        &dbc(),
        "--allow-send",
        "--foxglove",
        "127.0.0.1:0",
    ]);
    let foxglove = web
        .lines
        .next()
        .unwrap()
        .unwrap()
        .strip_prefix("Foxglove also on ws://")
        .unwrap()
        .to_string();
    let mut dump = Command::new(env!("CARGO_BIN_EXE_bywire"))
        .args(["dump", "--dbc", &dbc(), &format!("tug={bus}")])
        .stdout(std::fs::File::create(&dumped).unwrap())
        .spawn()
        .unwrap();
    let (client, mut lines) = foxglove_client(&foxglove, "tug", "VehicleToAds_State", 3);
    // Probes until dump listens (the client passes them over).
    for _ in 0..100 {
        send(&[bus, "7FE#00"]);
        if std::fs::metadata(&dumped).map(|m| m.len()).unwrap_or(0) > 0 {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    send(&[
        "--dbc",
        &dbc(),
        bus,
        "VehicleToAds_State",
        "VelocityActual=3.5",
        "Gear=Drive",
        "SteeringAngleActual=-7.2",
        "ControlMode=Autonomous",
    ]);
    send(&[bus, "1ABCDEF0#0102"]);
    send(&[bus, "7FF#00"]);
    let said: serde_json::Value =
        serde_json::from_str(&lines.next().expect("the client's result").unwrap()).unwrap();
    assert!(client.wait_with_output().unwrap().status.success());
    let text = wait_for_lines(&dumped, " 123 ", 1);
    let text = wait_for_lines(&dumped, " 100 ", 1).max(text);
    let _ = dump.kill();
    let _ = dump.wait();
    web.stop();

    // The channels: raw, statistics and one per message, with their schemas.
    let topics: Vec<&str> = said["topics"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| t["topic"].as_str().unwrap())
        .collect();
    assert_eq!(
        topics[..4],
        [
            "/tug/frames",
            "/tug/stats",
            "/tug/batch",
            "/tug/EmergencyBrake"
        ]
    );
    assert!(topics.contains(&"/tug/VehicleToAds_State"), "{topics:?}");
    for topic in said["topics"].as_array().unwrap() {
        assert_eq!(topic["encoding"], "json");
        let schema: serde_json::Value =
            serde_json::from_str(topic["schema"].as_str().unwrap()).unwrap();
        assert_eq!(schema["type"], "object", "{topic}");
    }
    assert_eq!(said["serverInfo"]["capabilities"][0], "clientPublish");

    // Raw frames: as dump printed them (bus label, identifier, length, bytes).
    let dump_frames: Vec<Vec<String>> = text
        .lines()
        .filter(|l| l.starts_with("  ") && !l.starts_with("      ") && !l.contains(" 7FE "))
        .map(|l| l.split_whitespace().map(String::from).collect())
        .collect();
    let raw: Vec<Vec<String>> = said["raw"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| {
            let m = &r["message"];
            let id = m["id"].as_u64().unwrap();
            let id = if m["extended"].as_bool().unwrap() {
                format!("{id:08X}")
            } else {
                format!("{id:03X}")
            };
            let data: Vec<String> = m["data"]
                .as_array()
                .unwrap()
                .iter()
                .map(|b| format!("{:02X}", b.as_u64().unwrap()))
                .collect();
            [
                vec![
                    m["bus"].as_str().unwrap().to_string(),
                    id,
                    format!("[{}]", data.len()),
                ],
                data,
            ]
            .concat()
        })
        .collect();
    // (What the client then published is in the trace too, after the three frames sent.)
    assert_eq!(raw, dump_frames, "{text}");

    // The decoded message: each signal as dump printed it (value names for named values).
    let decoded = &said["decoded"][0]["message"];
    let block: Vec<&str> = text
        .lines()
        .skip_while(|l| !l.contains("VehicleToAds_State("))
        .skip(1)
        .take_while(|l| !l.trim().starts_with(')'))
        .collect();
    assert_eq!(block.len(), 13, "{text}");
    for line in block {
        let (name, value) = line.trim().trim_end_matches(',').split_once(": ").unwrap();
        let shown = value.split(' ').next().unwrap();
        match decoded.get(format!("{name}_choice")) {
            Some(serde_json::Value::String(choice)) => assert_eq!(choice, shown, "{name}"),
            _ => assert_eq!(
                decoded[name].as_f64().unwrap(),
                shown.parse::<f64>().unwrap(),
                "{name}"
            ),
        }
    }
    assert_eq!(decoded["VelocityActual"], 3.5);
    assert_eq!(decoded["ControlMode_choice"], "Autonomous");

    // What it published: on the bus; the value out of range refused with a status.
    assert!(
        dump_frames
            .iter()
            .any(|f| f.join(" ") == "tug 123 [4] DE AD BE EF"),
        "{text}"
    );
    assert!(
        text.contains("VelocityCmd: 2.5 m/s") && text.contains("GearCmd: Reverse"),
        "{text}"
    );
    assert_eq!(text.matches("AdsToVehicle_Control(").count(), 1, "{text}");
    let statuses = said["statuses"].to_string();
    assert!(statuses.contains("VelocityCmd"), "{statuses}");
}

/// `bywire sim --web`: Foxglove's own client receives the tug's pose and route, valid against
/// Foxglove's own schemas (`@foxglove/schemas`, checked with python's jsonschema), and the
/// page's E-stop (a message on `/tug/command`) stops the tug.
#[test]
fn the_simulated_tug_reaches_foxglove_and_takes_the_pages_estop() {
    let scratch = Scratch::new("web-sim");
    let mut sim = Command::new(env!("CARGO_BIN_EXE_bywire"))
        .args([
            "sim",
            "--web",
            "127.0.0.1:0",
            "--no-view",
            "--max-seconds",
            "300",
        ])
        .args(["--out", scratch.join("run").to_str().unwrap()])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(sim.stdout.take().unwrap()).lines();
    let address = lines
        .by_ref()
        .map_while(Result::ok)
        .find_map(|l| {
            l.strip_prefix("the page on http://")
                .map(|rest| rest.split('/').next().unwrap().to_string())
        })
        .expect("the sim says where its page is");
    let client = Command::new("node")
        .arg(format!("{}/foxglove_sim.js", common::oracles()))
        .arg(format!("ws://{address}"))
        .env("NODE_PATH", node_modules())
        .output()
        .unwrap();
    Command::new("kill")
        .args(["-INT", &sim.id().to_string()])
        .status()
        .unwrap();
    // The rest of its output, then its end.
    let rest: Vec<String> = lines.map_while(Result::ok).collect();
    assert!(sim.wait().unwrap().success(), "{rest:?}");
    assert!(
        client.status.success(),
        "{}",
        String::from_utf8_lossy(&client.stderr)
    );
    let said = String::from_utf8_lossy(&client.stdout).into_owned();
    let result: serde_json::Value = serde_json::from_str(said.trim()).unwrap();
    assert_eq!(result["channels"]["/tug/pose"], "foxglove.PoseInFrame");
    assert_eq!(result["channels"]["/tug/route"], "foxglove.PosesInFrame");
    let states = result["states"].as_array().unwrap();
    assert_ne!(states.last().unwrap()["estop"], "Normal", "{states:?}");
    // Every pose and the route, against Foxglove's own schemas.
    let file = scratch.join("received.json");
    std::fs::write(&file, &said).unwrap();
    let checked = Command::new("python3")
        .args([
            "-c",
            "import json, sys, jsonschema\n\
             r = json.load(open(sys.argv[1]))\n\
             for pose in r['poses']:\n\
             \x20   jsonschema.validate(pose, r['schemas']['PoseInFrame'])\n\
             \x20   q = pose['pose']['orientation']\n\
             \x20   assert abs(q['x']**2 + q['y']**2 + q['z']**2 + q['w']**2 - 1) < 1e-9, q\n\
             jsonschema.validate(r['route'], r['schemas']['PosesInFrame'])\n\
             assert len(r['route']['poses']) > 10\n\
             times = [p['timestamp']['sec'] * 10**9 + p['timestamp']['nsec'] for p in r['poses']]\n\
             assert times == sorted(times) and len(set(times)) == len(times), times\n\
             print(len(r['poses']))",
            file.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(
        checked.status.success(),
        "{}",
        String::from_utf8_lossy(&checked.stderr)
    );
}

/// Start Foxglove's client (`foxglove_client.js`) on `address` for `bus` and `message`; its
/// output lines, the first being "ready".
fn foxglove_client(
    address: &str,
    bus: &str,
    message: &str,
    raw: usize,
) -> (Child, std::io::Lines<BufReader<std::process::ChildStdout>>) {
    let mut client = Command::new("node")
        .arg(format!("{}/foxglove_client.js", common::oracles()))
        .args([
            &format!("ws://{address}"),
            bus,
            message,
            &raw.to_string(),
            "1",
        ])
        .env("NODE_PATH", node_modules())
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(client.stdout.take().unwrap()).lines();
    assert_eq!(lines.next().unwrap().unwrap(), "ready");
    (client, lines)
}

/// The address a `bywire` command announces its page on, from its output.
fn announced(lines: &mut impl Iterator<Item = std::io::Result<String>>) -> String {
    lines
        .map_while(Result::ok)
        .find_map(|l| {
            l.strip_prefix("the page on http://")
                .map(|rest| rest.split('/').next().unwrap().to_string())
        })
        .expect("the page's address")
}

/// `bywire record --foxglove`: what it records, Foxglove's client sees decoded; it sends
/// nothing (a recorder only listens).
#[test]
fn record_shows_what_it_records_to_foxglove_and_sends_nothing() {
    if !inside_lonet("record_shows_what_it_records_to_foxglove_and_sends_nothing") {
        return;
    }
    let bus = "udp:239.74.163.2:43622";
    let scratch = Scratch::new("web-record");
    let mut record = Command::new(env!("CARGO_BIN_EXE_bywire"))
        .args(["record", &format!("tug={bus}"), "--quiet", "--dbc", &dbc()])
        .args(["--out", scratch.join("logs").to_str().unwrap()])
        .args(["--foxglove", "127.0.0.1:0"])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut record_out = BufReader::new(record.stdout.take().unwrap()).lines();
    let address = announced(&mut record_out);
    let (client, mut lines) = foxglove_client(&address, "tug", "VehicleToAds_State", 2);
    send(&[
        "--dbc",
        &dbc(),
        bus,
        "VehicleToAds_State",
        "VelocityActual=1.25",
    ]);
    send(&[bus, "1ABCDEF0#0102"]);
    let said: serde_json::Value =
        serde_json::from_str(&lines.next().expect("the client's result").unwrap()).unwrap();
    assert!(client.wait_with_output().unwrap().status.success());
    Command::new("kill")
        .args(["-INT", &record.id().to_string()])
        .status()
        .unwrap();
    let files: Vec<String> = record_out.map_while(Result::ok).collect();
    assert!(record.wait().unwrap().success(), "{files:?}");
    assert_eq!(said["decoded"][0]["message"]["VelocityActual"], 1.25);
    let ids: Vec<u64> = said["raw"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["message"]["id"].as_u64().unwrap())
        .collect();
    assert_eq!(
        ids,
        [0x101, 0x1ABC_DEF0],
        "nothing sent by the client: {said}"
    );
    assert_eq!(said["serverInfo"]["capabilities"], serde_json::json!([]));
    assert!(
        said["statuses"].to_string().contains("--allow-send"),
        "{said}"
    );
    assert!(files.iter().any(|f| f.contains(" 2 frames")), "{files:?}");
}

/// `bywire serve --foxglove`: socketcand clients and Foxglove's client on one bus; what the
/// Foxglove client publishes goes on the bus.
#[test]
fn serve_speaks_socketcand_and_foxglove_on_one_bus() {
    let mut serve = Command::new(env!("CARGO_BIN_EXE_bywire"))
        .args(["serve", "virtual:web-serve", "--listen", "127.0.0.1:0"])
        .args(["--foxglove", "127.0.0.1:0", "--db", &dbc(), "--allow-send"])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut out = BufReader::new(serve.stdout.take().unwrap()).lines();
    let socketcand = out
        .next()
        .unwrap()
        .unwrap()
        .rsplit(" on ")
        .next()
        .unwrap()
        .trim_end_matches(" (socketcand)")
        .to_string();
    let address = announced(&mut out);
    let (client, mut lines) =
        foxglove_client(&address, "virtual:web-serve", "VehicleToAds_State", 1);
    let bus = format!("socketcand:{socketcand}/web-serve");
    let (code, _, err) = common::bywire(
        &[
            "send",
            "--dbc",
            &dbc(),
            &bus,
            "VehicleToAds_State",
            "Gear=Reverse",
        ],
        "",
    );
    assert_eq!(code, 0, "{err}");
    let said: serde_json::Value =
        serde_json::from_str(&lines.next().expect("the client's result").unwrap()).unwrap();
    assert!(client.wait_with_output().unwrap().status.success());
    Command::new("kill")
        .args(["-INT", &serve.id().to_string()])
        .status()
        .unwrap();
    assert!(serve.wait().unwrap().success());
    assert_eq!(said["decoded"][0]["message"]["Gear_choice"], "Reverse");
    let frames: Vec<String> = said["raw"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| format!("{:03X}", r["message"]["id"].as_u64().unwrap()))
        .collect();
    // Its own frames, as the bus carried them: the raw one and the encoded message.
    assert_eq!(frames, ["101", "123", "100"], "{said}");
}

/// Logs on the page: one of each format (converted from the example candump log) opens with
/// its frames; a signal plotted from a log has cantools' values; play, step and export work
/// (`web_logs.py`, in Chromium).
#[test]
fn logs_of_every_format_open_play_plot_and_export_on_the_page() {
    let scratch = Scratch::new("web-logs");
    let example = format!(
        "{}/../../examples/data/candump.log",
        env!("CARGO_MANIFEST_DIR")
    );
    let candump = scratch.join("candump.log");
    std::fs::copy(&example, &candump).unwrap();
    let mut logs = vec![candump.clone()];
    for extension in ["asc", "blf", "trc", "pcapng", "mf4", "mcap", "parquet"] {
        let out = scratch.join(format!("drive.{extension}"));
        let (code, _, err) = common::bywire(
            &[
                "log",
                "convert",
                candump.to_str().unwrap(),
                out.to_str().unwrap(),
            ],
            "",
        );
        assert_eq!(code, 0, "{err}");
        logs.push(out);
    }
    let mut args: Vec<String> = vec!["--db".into(), dbc()];
    for log in &logs {
        args.push("-I".into());
        args.push(log.to_str().unwrap().into());
    }
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let web = Web::start(&args);
    let shots = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../target/web-screenshots");
    std::fs::create_dir_all(&shots).unwrap();
    let out = Command::new("python3")
        .arg(format!("{}/web_logs.py", common::oracles()))
        .args([
            &format!("http://{}/", web.address),
            candump.to_str().unwrap(),
            &dbc(),
            shots.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    web.stop();
    assert!(
        out.status.success(),
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}
