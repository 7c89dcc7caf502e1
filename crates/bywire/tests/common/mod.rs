//! Helpers shared by the integration tests: run a program with standard input, find corpus files.
// Each test file uses some of these.
#![allow(dead_code, clippy::unwrap_used, clippy::expect_used)]

use std::io::Write;
use std::process::{Command, Stdio};

/// Run `command` with `input` on standard input: (exit code, stdout, stderr).
pub fn run_with_input(command: &mut Command, input: &str) -> (i32, String, String) {
    let mut child = command
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the program starts");
    // A program that refuses its arguments may exit before reading its input: a broken
    // pipe here is its choice, not a failure of the test.
    let written = child.stdin.take().unwrap().write_all(input.as_bytes());
    if let Err(e) = written {
        assert_eq!(e.kind(), std::io::ErrorKind::BrokenPipe, "{e}");
    }
    let out = child.wait_with_output().unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8(out.stdout).unwrap(),
        String::from_utf8(out.stderr).unwrap(),
    )
}

/// Run the `bywire` binary.
pub fn bywire(args: &[&str], input: &str) -> (i32, String, String) {
    run_with_input(Command::new(env!("CARGO_BIN_EXE_bywire")).args(args), input)
}

/// A file of the shared DBC corpus.
pub fn corpus(file: &str) -> String {
    format!(
        "{}/../../../shared/corpus/dbc/{file}",
        env!("CARGO_MANIFEST_DIR")
    )
}

/// Run a shell script in the SocketCAN VM (`../shared/tools/canvm.sh run OPTIONS -- sh -c
/// SCRIPT`) and return what it printed; panics with the VM's output if it failed.
pub fn in_canvm(options: &[&str], script: &str) -> String {
    let canvm = format!(
        "{}/../../../shared/tools/canvm.sh",
        env!("CARGO_MANIFEST_DIR")
    );
    let out = Command::new(canvm)
        .arg("run")
        .args(options)
        .args(["--timeout", "300", "--", "/bin/sh", "-c", script])
        .output()
        .expect("canvm.sh runs (see ../shared/tools/README.md)");
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "canvm failed: {text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    text
}

/// A command's stdout as JSON lines, after checking it succeeded (its stderr shown if not).
pub fn json_lines(out: std::process::Output) -> Vec<serde_json::Value> {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}
