//! The README's commands run as written: every command of the indented blocks from "A
//! ten-minute tour" to the benchmarks, in the README's order (later ones read what earlier ones
//! wrote), from a folder holding the repository's `examples/`, `crates/` and `campaigns/`, with
//! this `bywire` first on the path. Those on SocketCAN interfaces run in the SocketCAN VM on
//! vcan interfaces of those names; terminal views in tmux; the rest on this machine, inside a
//! private network namespace (`dump udp:` is multicast). A few are run by the test named beside
//! them instead. The Python blocks are run by `python/tests/test_readme.py`.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

mod common;

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::{inside_lonet, Scratch, Session};

/// How one of the README's commands is run.
#[derive(Debug, Clone, Copy, PartialEq)]
enum How {
    /// It ends by itself, with status 0.
    Exits,
    /// It runs until stopped (a server): it must still be running once it has said something
    /// (or after 10 s), and end with status 0 on Ctrl-C.
    UntilStopped,
    /// A terminal view: in tmux until it shows `ready`, then q, status 0.
    Terminal(&'static str),
    /// On SocketCAN interfaces: in the VM; one that runs until stopped is left running while
    /// the following ones run (as in another terminal), then stopped.
    Vm { until_stopped: bool },
    /// Run by the test named.
    Elsewhere(&'static str),
}

/// The commands a README line may start with; other indented lines are output, Python or
/// continuations.
const COMMANDS: [&str; 6] = [
    "bywire ", "candump ", "chmod ", "cargo ", "pip ", "python3 ",
];

/// Commands run elsewhere: (the line's start, the test that runs it).
const ELSEWHERE: [(&str, &str); 6] = [
    (
        "cargo build --release",
        "the build itself: this test runs the build under test",
    ),
    (
        "cargo run --release -- sim --ros2",
        "ros2::the_readme_python_script_drives_the_simulated_tug",
    ),
    (
        "pip install cyclonedds",
        "ros2::the_readme_python_script_drives_the_simulated_tug",
    ),
    (
        "python3 examples/ros2_drive_tug.py",
        "ros2::the_readme_python_script_drives_the_simulated_tug",
    ),
    (
        "bywire campaign campaigns/default.toml --out",
        "campaign_cli and bywire-sim's campaign tests (the whole campaign, minutes)",
    ),
    (
        "bywire campaign campaigns/default.toml --disable",
        "bywire-sim's campaign tests (each mechanism switched off)",
    ),
];

/// Commands on SocketCAN that run until stopped.
const VM_SERVERS: [&str; 8] = [
    "candump ",
    "bywire dump ",
    "bywire busload ",
    "bywire record ",
    "bywire sniff ",
    "bywire vehicle ",
    "bywire canopen node ",
    "bywire ros2 ",
];

/// Commands on this machine that run until stopped.
const SERVERS: [&str; 5] = [
    "bywire serve ",
    "bywire slcan-adapter ",
    "bywire dump udp:",
    "bywire web ",
    "bywire sim --web",
];

/// What some commands must print (stdout and stderr together), beyond ending well.
const SAYS: [(&str, &str); 6] = [
    ("bywire sim --fast --seed 7", "m sideways"),
    (
        "bywire bridge --profile reference-tug sim:demo",
        "\"velocity\":1.5",
    ),
    (
        "bywire bridge --profile examples/data/secured.toml",
        "\"mode\":\"autonomous\"",
    ),
    ("bywire bittiming --clock 40000000", "longest bus about"),
    ("bywire canopen sdo can0 1 read 0x1008", "MDC"),
    ("bywire --version", "commit"),
];

/// The README's commands in order, continuation lines joined.
fn commands(readme: &str) -> Vec<String> {
    let mut in_scope = false;
    let mut fenced = false;
    let mut commands: Vec<String> = Vec::new();
    let mut continued = false;
    for line in readme.lines() {
        if line.starts_with("## ") {
            in_scope =
                line == "## A ten-minute tour" || (in_scope && !line.starts_with("## Benchmarks"));
        }
        if line.starts_with("```") {
            fenced = !fenced;
        }
        let Some(code) = line.strip_prefix("    ") else {
            continue;
        };
        if !in_scope || fenced {
            continue;
        }
        let code = code.trim();
        if continued {
            let last = commands.last_mut().unwrap();
            last.truncate(last.trim_end_matches('\\').trim_end().len());
            last.push(' ');
            last.push_str(code);
        } else if COMMANDS.iter().any(|c| code.starts_with(c)) {
            commands.push(code.to_string());
        } else {
            continue;
        }
        continued = code.ends_with('\\');
    }
    commands
}

/// Whether `command` names a SocketCAN interface (`can0`, `vcan1`, ...) as a word.
fn on_socketcan(command: &str) -> bool {
    command
        .split(|c: char| !c.is_ascii_alphanumeric())
        .any(|word| {
            let digits = word
                .strip_prefix("vcan")
                .or_else(|| word.strip_prefix("can"));
            digits.is_some_and(|d| !d.is_empty() && d.chars().all(|c| c.is_ascii_digit()))
        })
}

fn how(command: &str) -> How {
    if let Some((_, test)) = ELSEWHERE
        .iter()
        .find(|(start, _)| command.starts_with(start))
    {
        return How::Elsewhere(test);
    }
    if on_socketcan(command) {
        let until_stopped = VM_SERVERS.iter().any(|s| command.starts_with(s));
        return How::Vm { until_stopped };
    }
    if command.starts_with("bywire monitor ") {
        return How::Terminal("AdsToVehicle_Control");
    }
    if SERVERS.iter().any(|s| command.starts_with(s)) {
        return How::UntilStopped;
    }
    How::Exits
}

/// A scratch folder standing in for the repository's root: its `examples`, `crates` and
/// `campaigns` are the repository's (read-only use; `examples/data/demo.keys` is copied, as the
/// README's `chmod` changes it).
fn workspace(name: &str) -> (Scratch, PathBuf) {
    let dir = Scratch::new(name);
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    for link in ["crates", "campaigns"] {
        std::os::unix::fs::symlink(root.join(link), dir.join(link)).unwrap();
    }
    let data = dir.join("examples/data");
    std::fs::create_dir_all(&data).unwrap();
    for entry in std::fs::read_dir(root.join("examples/data")).unwrap() {
        let entry = entry.unwrap();
        // Links are kept as links (the profile finds its DBC beside it).
        match std::fs::read_link(entry.path()) {
            Ok(target) => std::os::unix::fs::symlink(
                root.join("examples/data")
                    .join(target)
                    .canonicalize()
                    .unwrap(),
                data.join(entry.file_name()),
            )
            .unwrap(),
            Err(_) => {
                std::fs::copy(entry.path(), data.join(entry.file_name())).unwrap();
            }
        }
    }
    let bin = dir.join("bin");
    std::fs::create_dir_all(&bin).unwrap();
    std::os::unix::fs::symlink(env!("CARGO_BIN_EXE_bywire"), bin.join("bywire")).unwrap();
    (dir, bin)
}

/// `sh -c command` in `dir` with `bin` first on the path.
fn shell(dir: &Path, bin: &Path, command: &str) -> Command {
    let mut shell = Command::new("sh");
    shell
        .arg("-c")
        .arg(command)
        .current_dir(dir)
        .env(
            "PATH",
            format!("{}:{}", bin.display(), std::env::var("PATH").unwrap()),
        )
        .stdin(Stdio::null());
    shell
}

/// Check `said` for what `command` must print.
fn check_says(command: &str, said: &str) {
    for (start, text) in SAYS {
        if command.starts_with(start) {
            assert!(said.contains(text), "{command}: '{text}' not in:\n{said}");
        }
    }
}

fn run_exits(dir: &Path, bin: &Path, command: &str) {
    let out = shell(dir, bin, command).output().unwrap();
    let said = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.status.success(), "{command}: {}\n{said}", out.status);
    check_says(command, &said);
}

fn run_until_stopped(dir: &Path, bin: &Path, command: &str) {
    let mut child = shell(dir, bin, &format!("exec {command}"))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Ready once it has said something on either stream (a server names where it listens),
    // or after 10 s; what it says after that is read and dropped.
    let (said, heard) = std::sync::mpsc::channel();
    let streams: [Box<dyn Read + Send>; 2] = [
        Box::new(child.stdout.take().unwrap()),
        Box::new(child.stderr.take().unwrap()),
    ];
    for mut stream in streams {
        let said = said.clone();
        std::thread::spawn(move || {
            let mut first = [0u8; 1];
            if stream.read(&mut first).is_ok_and(|n| n > 0) {
                let _ = said.send(());
            }
            let _ = std::io::copy(&mut stream, &mut std::io::sink());
        });
    }
    let deadline = Instant::now() + Duration::from_secs(10);
    while Instant::now() < deadline && heard.try_recv().is_err() {
        std::thread::sleep(Duration::from_millis(50));
    }
    assert!(
        child.try_wait().unwrap().is_none(),
        "{command}: ended before it was stopped"
    );
    let interrupted = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(interrupted.success());
    let deadline = Instant::now() + Duration::from_secs(15);
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        assert!(
            Instant::now() < deadline,
            "{command}: Ctrl-C did not end it"
        );
        std::thread::sleep(Duration::from_millis(50));
    };
    assert!(status.success(), "{command}: {status} on Ctrl-C");
}

fn run_terminal(dir: &Path, bin: &Path, command: &str, ready: &str) {
    let session = Session::start(
        "readme",
        &format!(
            // The command on a line of its own: a trailing comment ends there.
            "cd {} && export PATH={}:$PATH\n{command}\necho exit=$?; sleep 60",
            dir.display(),
            bin.display()
        ),
    );
    session.wait_for(ready);
    session.keys("q");
    session.wait_for("exit=0");
}

/// The VM's part: one script, the servers left running in the background until the end (then
/// SIGTERM, as systemd stops a service), every status printed as `== N exit S`.
fn run_in_vm(dir: &Path, commands: &[(usize, &str, bool)]) -> String {
    let bin = env!("CARGO_BIN_EXE_bywire");
    let mut script = format!(
        "set -u\nexport TERM=xterm\nmkdir -p /tmp/bin && ln -sf {bin} /tmp/bin/bywire && export PATH=/tmp/bin:$PATH\n\
         for i in can0 can1 can2 vcan0 vcan1; do ip link add $i type vcan 2>/dev/null; ip link set $i up; done\n\
         cd {}\nSERVERS=\n",
        dir.display()
    );
    for (n, command, until_stopped) in commands {
        let quoted = command.replace('\'', "'\\''");
        if *until_stopped {
            // A session of its own, so stopping it stops a whole pipeline; its shell outlives
            // the signal (a handler, which its commands do not inherit) to give their status.
            // A terminal view gets a terminal: util-linux's `script` (its status the view's).
            let run = if command.starts_with("bywire sniff ") {
                format!("script -qefc \"$0\" /dev/null' '{quoted}")
            } else {
                quoted
            };
            script += &format!(
                "setsid sh -c 'trap : TERM; {run}' > vm.{n}.out 2>&1 &\nSERVERS=\"$SERVERS {n}:$!\"\n"
            );
            // Ready: a CANopen node once its heartbeat is on the bus, a listener at once, the
            // rest once they have said something (a node its name, a view its screen).
            if command.starts_with("bywire canopen node can0") {
                script += "candump -n 1 -T 20000 can0,701:7FF > /dev/null\n";
            } else if !["candump ", "bywire dump "]
                .iter()
                .any(|l| command.starts_with(l))
            {
                script += &format!(
                    "for i in $(seq 300); do [ -s vm.{n}.out ] && break; sleep 0.1; done\n"
                );
            }
        } else {
            script += &format!(
                "timeout -s TERM 120 sh -c '{quoted}' > vm.{n}.out 2>&1; echo \"== {n} exit $?\"\n"
            );
        }
    }
    // Every server stopped at once; one still running 15 s later is killed and named.
    script += "for s in $SERVERS; do busybox kill -TERM -${s#*:} 2>/dev/null; done\n\
               for i in $(seq 150); do alive=; for s in $SERVERS; do kill -0 ${s#*:} 2>/dev/null && alive=1; done; [ -z \"$alive\" ] && break; sleep 0.1; done\n\
               for s in $SERVERS; do kill -0 ${s#*:} 2>/dev/null && { echo \"== ${s%%:*} still running\"; busybox kill -KILL -${s#*:}; }; done\n\
               for s in $SERVERS; do wait ${s#*:}; echo \"== ${s%%:*} exit $?\"; done\n\
               for f in vm.*.out; do echo \"== output $f\"; tail -n 20 $f; done\n";
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let mut options: Vec<String> = [
        "--can-utils",
        "--include",
        bin,
        "--include",
        "/usr/bin/script",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    // The data the commands read, at its path in the scratch folder, and what its links name.
    options.extend([
        "--include".into(),
        dir.join("examples/data").display().to_string(),
    ]);
    for linked in ["dbc/reference-tug.dbc", "profiles/reference-tug.toml"] {
        let path = root.join("crates/bywire-tug").join(linked);
        options.extend([
            "--include".into(),
            path.canonicalize().unwrap().display().to_string(),
        ]);
    }
    let options: Vec<&str> = options.iter().map(String::as_str).collect();
    common::in_canvm(&options, &script)
}

#[test]
fn every_readme_command_runs_as_written() {
    if !inside_lonet("every_readme_command_runs_as_written") {
        return;
    }
    let readme =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../../README.md"))
            .unwrap();
    let commands = commands(&readme);
    assert!(commands.len() > 60, "{commands:#?}");
    let (dir, bin) = workspace("readme");
    let mut in_vm = Vec::new();
    for (n, command) in commands.iter().enumerate() {
        let started = Instant::now();
        match how(command) {
            How::Exits => run_exits(&dir, &bin, command),
            How::UntilStopped => run_until_stopped(&dir, &bin, command),
            How::Terminal(ready) => run_terminal(&dir, &bin, command, ready),
            How::Vm { until_stopped } => in_vm.push((n, command.as_str(), until_stopped)),
            How::Elsewhere(test) => {
                println!("{command}: run by {test}");
                continue;
            }
        }
        println!("{:5.1} s  {command}", started.elapsed().as_secs_f64());
    }
    let out = run_in_vm(&dir, &in_vm);
    for (n, command, _) in &in_vm {
        let status = format!("== {n} exit ");
        let at = out
            .find(&status)
            .unwrap_or_else(|| panic!("{command}: no status in\n{out}"));
        let code = out[at + status.len()..].split_whitespace().next().unwrap();
        let said = out
            .split(&format!("== output vm.{n}.out\n"))
            .nth(1)
            .map(|rest| rest.split("\n== output ").next().unwrap_or(rest))
            .unwrap_or_default();
        assert_eq!(code, "0", "{command}:\n{said}");
        check_says(command, said);
    }
}

#[test]
fn commands_are_read_from_the_readme_as_a_reader_sees_them() {
    let text = "## A ten-minute tour\n\n    bywire a   # note\n    # output\n    bywire b \\\n        --c\n\n```\n    bywire fenced\n```\n    import x\n## Benchmarks\n    bywire bench\n";
    assert_eq!(commands(text), ["bywire a   # note", "bywire b --c"]);
    assert!(on_socketcan("bywire dump -ta can0,123:7FF vcan1"));
    assert!(on_socketcan("bywire play -I x.log vcan0=bus1"));
    assert!(!on_socketcan("bywire bridge sim:demo@500000 virtual:can"));
    assert_eq!(how("bywire serve virtual:test"), How::UntilStopped);
    assert_eq!(
        how("bywire vehicle --profile p vcan0"),
        How::Vm {
            until_stopped: true
        }
    );
    assert_eq!(
        how("bywire send can0 123#00"),
        How::Vm {
            until_stopped: false
        }
    );
}
