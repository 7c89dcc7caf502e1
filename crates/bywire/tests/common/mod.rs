//! Helpers shared by the integration tests: run a program with standard input, find corpus files.
// Each test file uses some of these.
#![allow(dead_code, clippy::unwrap_used, clippy::expect_used)]

use std::io::Write;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Run `command` with `input` on standard input: (exit code, stdout, stderr).
pub fn run_with_input(command: &mut Command, input: &str) -> (i32, String, String) {
    let mut child = command
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the program starts");
    // Written from a thread while the output is read: a program that answers as it reads
    // would otherwise fill its output pipe and wait for us as we wait for it. A program that
    // refuses its arguments may exit before reading its input: a broken pipe here is its
    // choice, not a failure of the test.
    let mut stdin = child.stdin.take().unwrap();
    let input = input.to_string();
    let writer = std::thread::spawn(move || stdin.write_all(input.as_bytes()));
    let out = child.wait_with_output().unwrap();
    if let Err(e) = writer.join().unwrap() {
        assert_eq!(e.kind(), std::io::ErrorKind::BrokenPipe, "{e}");
    }
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
    // The guest's files live in its memory: the debug binary (about 300 MB with DDS), what a
    // test includes and what it writes need more than the default 1 GiB (a test's own
    // `--mem` comes later and wins).
    let run = || {
        Command::new(&canvm)
            .arg("run")
            .args(["--mem", "2048"])
            .args(options)
            .args(["--timeout", "300", "--", "/bin/sh", "-c", script])
            .output()
            .expect("canvm.sh runs (see ../shared/tools/README.md)")
    };
    let mut out = run();
    // Two VMs started at once on a fresh machine both build canvm's cache and one loses the
    // race for its file (`mv: cannot stat .../canvm-cache/...tmp`): the cache is there now.
    let lost_race = |out: &std::process::Output| {
        [&out.stdout, &out.stderr]
            .iter()
            .any(|o| String::from_utf8_lossy(o).contains("canvm-cache/"))
    };
    if !out.status.success() && lost_race(&out) {
        out = run();
    }
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

/// True inside `../shared/tools/lonet.sh` (a private network namespace where multicast and DDS
/// cannot leave the machine); on the host, re-runs `test` of this binary in a fresh one and
/// checks that it passed.
pub fn inside_lonet(test: &str) -> bool {
    const MARKER: &str = "BYWIRE_IN_LONET";
    if std::env::var_os(MARKER).is_some() {
        return true;
    }
    let lonet = format!(
        "{}/../../../shared/tools/lonet.sh",
        env!("CARGO_MANIFEST_DIR")
    );
    let out = Command::new(lonet)
        .arg(std::env::current_exe().unwrap())
        .args(["--exact", test, "--nocapture", "--test-threads", "1"])
        .env(MARKER, "1")
        .output()
        .expect("lonet.sh runs (see ../shared/tools/README.md)");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success() && text.contains("test result: ok. 1 passed"),
        "{test} in lonet: {text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    false
}

/// The test oracles' folder (Python peers and their shared modules).
pub fn oracles() -> String {
    format!("{}/tests/oracles", env!("CARGO_MANIFEST_DIR"))
}

/// A background `bywire` that is stopped (SIGTERM, as Ctrl-C) and collected when dropped or
/// by [`Background::stop`].
pub struct Background(Option<std::process::Child>);

impl Background {
    /// Start `bywire ARGS` with its output captured.
    pub fn start(args: &[&str]) -> Background {
        let child = Command::new(env!("CARGO_BIN_EXE_bywire"))
            .args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("bywire starts");
        Background(Some(child))
    }

    /// Its process id.
    pub fn id(&self) -> u32 {
        self.0.as_ref().map_or(0, std::process::Child::id)
    }

    /// Stop it as Ctrl-C would and return (exit code, stdout, stderr).
    pub fn stop(mut self) -> (i32, String, String) {
        let child = self.0.take().unwrap();
        let _ = Command::new("kill")
            .args(["-TERM", &child.id().to_string()])
            .status();
        let out = child.wait_with_output().unwrap();
        (
            out.status.code().unwrap_or(-1),
            String::from_utf8_lossy(&out.stdout).into_owned(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    }
}

impl Drop for Background {
    fn drop(&mut self) {
        if let Some(mut child) = self.0.take() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

/// The text between `== name` and the next `==` line of a script's output.
pub fn section<'a>(text: &'a str, name: &str) -> &'a str {
    let start = text
        .find(&format!("== {name}\n"))
        .unwrap_or_else(|| panic!("no section {name} in:\n{text}"));
    let rest = &text[start + name.len() + 4..];
    &rest[..rest.find("\n== ").map_or(rest.len(), |e| e + 1)]
}

/// A test's own folder under the temporary directory (`bywire-NAME-PID`), made empty; removed
/// when the test passes, kept for a look when it fails.
pub struct Scratch(std::path::PathBuf);

impl Scratch {
    pub fn new(name: &str) -> Scratch {
        let dir = std::env::temp_dir().join(format!("bywire-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        Scratch(dir)
    }
}

impl std::ops::Deref for Scratch {
    type Target = std::path::Path;
    fn deref(&self) -> &std::path::Path {
        &self.0
    }
}

impl AsRef<std::path::Path> for Scratch {
    fn as_ref(&self) -> &std::path::Path {
        &self.0
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        if std::thread::panicking() {
            eprintln!("kept for a look: {}", self.0.display());
        } else {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

impl AsRef<std::ffi::OsStr> for Scratch {
    fn as_ref(&self) -> &std::ffi::OsStr {
        self.0.as_os_str()
    }
}

/// A session running `command` on a tmux server of its own, closed when dropped. Its own server
/// (`-L`): tests run in parallel, and several clients starting the one default server at the
/// same moment can fail to reach it.
pub struct Session(String);

impl Session {
    pub fn start(name: &str, command: &str) -> Session {
        let session = Session(format!("{name}-{}", std::process::id()));
        let (ok, err) = session.tmux(&[
            "new-session",
            "-d",
            "-s",
            &session.0,
            "-x",
            "120",
            "-y",
            "30",
            command,
        ]);
        assert!(ok, "tmux new-session: {err}");
        session
    }

    /// Runs tmux on this session's server: whether it succeeded, and its output (stdout on
    /// success, stderr otherwise).
    pub fn tmux(&self, args: &[&str]) -> (bool, String) {
        let out = Command::new("tmux")
            .args(["-L", &self.0])
            .args(args)
            .output()
            .expect("tmux is installed (scripts/install-test-deps.sh)");
        let text = if out.status.success() {
            &out.stdout
        } else {
            &out.stderr
        };
        (
            out.status.success(),
            String::from_utf8_lossy(text).into_owned(),
        )
    }

    pub fn screen(&self) -> String {
        self.tmux(&["capture-pane", "-p", "-t", &self.0]).1
    }

    /// Wait until the screen contains `text`.
    pub fn wait_for(&self, text: &str) -> String {
        let deadline = Instant::now() + Duration::from_secs(15);
        loop {
            let screen = self.screen();
            if screen.contains(text) {
                return screen;
            }
            assert!(
                Instant::now() < deadline,
                "'{text}' never appeared:\n{screen}"
            );
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    pub fn keys(&self, keys: &str) {
        let (ok, err) = self.tmux(&["send-keys", "-t", &self.0, keys]);
        assert!(ok, "tmux send-keys: {err}");
    }

    pub fn wait_closed(&self) {
        let deadline = Instant::now() + Duration::from_secs(10);
        while self.tmux(&["has-session", "-t", &self.0]).0 {
            assert!(
                Instant::now() < deadline,
                "still running:\n{}",
                self.screen()
            );
            std::thread::sleep(Duration::from_millis(100));
        }
    }
}

impl Drop for Session {
    fn drop(&mut self) {
        // The server goes with its only session.
        let _ = self.tmux(&["kill-server"]);
    }
}
