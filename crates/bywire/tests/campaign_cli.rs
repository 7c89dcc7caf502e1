//! `bywire campaign`: the default campaign's reports as a CI reads them (JUnit XML checked by
//! Python's own XML parser, the cells as JSON), exit 1 with a mechanism switched off, and a
//! clear refusal when the campaign cannot show a switched-off mechanism missing.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use common::Scratch;

use std::path::Path;
use std::process::{Command, Output};

fn bywire(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_bywire"))
        .args(args)
        .output()
        .unwrap()
}

fn path(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn default_campaign() -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../campaigns/default.toml")
        .display()
        .to_string()
}

/// Verifies: REQ-FI-1.
#[test]
fn the_default_campaign_writes_junit_json_and_the_matrix_and_fails_without_a_mechanism() {
    let dir = Scratch::new("campaign");
    let out = dir.join("all");
    let run = bywire(&["campaign", &default_campaign(), "--out", path(&out)]);
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(stdout.contains("0 failed"), "{stdout}");
    // The JUnit file as a CI reads it: one test case per cell, named profile/state/fault/
    // mechanism, cells that do not apply skipped with their reason.
    let check = Command::new("python3")
        .args([
            "-c",
            r#"
import json, sys, xml.etree.ElementTree as ET
root = ET.parse(sys.argv[1] + "/junit.xml").getroot()
cases = root.findall(".//testcase")
cells = json.load(open(sys.argv[1] + "/cells.json"))
assert len(cases) == len(cells) == 540, (len(cases), len(cells))
assert not root.findall(".//failure")
skipped = root.findall(".//skipped")
assert len(skipped) == sum(c["verdict"] == "not-applicable" for c in cells)
assert all(s.get("message").startswith("not applicable: ") and len(s.get("message")) > 20 for s in skipped)
assert all(len(c.get("name").split("/")) == 4 for c in cases)
names = {c.get("name") for c in cases}
assert "reference-tug/cruising/node-silent/timeout" in names
assert "shuttle/cruising/out-of-range/range" in names
assert "reference-tug-redundant/cruising/angle-sensor/voter" in names
print("ok")
"#,
            path(&out),
        ])
        .output()
        .unwrap();
    assert!(
        check.status.success(),
        "{}",
        String::from_utf8_lossy(&check.stderr)
    );
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(html.contains("<h2>shuttle</h2>") && html.contains("class=\"pass\""));
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("| node-silent |"), "{md}");

    // Without the range check: exit 1, the failed cells named.
    let without = dir.join("without-range");
    let run = bywire(&[
        "campaign",
        &default_campaign(),
        "--disable",
        "range",
        "--out",
        path(&without),
    ]);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("FAIL reference-tug/cruising/out-of-range/range"),
        "{stderr}"
    );
    let md = std::fs::read_to_string(without.join("report.md")).unwrap();
    assert!(
        md.contains("Switched off in the vehicle's software: range"),
        "{md}"
    );

    // A campaign without the voter's faults cannot tell it missing.
    let text = std::fs::read_to_string(default_campaign()).unwrap();
    let first = text.find("[[fault]]").unwrap();
    let silent = text.find("class = \"node-silent\"").unwrap();
    let start = text[..silent].rfind("[[fault]]").unwrap();
    let end = text[silent..]
        .find("[[fault]]")
        .map_or(text.len(), |e| silent + e);
    let small = dir.join("small.toml");
    std::fs::write(&small, format!("{}{}", &text[..first], &text[start..end])).unwrap();
    let run = bywire(&[
        "campaign",
        path(&small),
        "--disable",
        "voter",
        "--out",
        path(&dir.join("without-voter")),
    ]);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("this campaign does not test it"),
        "{stderr}"
    );

    // A mechanism that is no mechanism, and a campaign that is no campaign.
    let run = bywire(&["campaign", &default_campaign(), "--disable", "crc"]);
    assert!(String::from_utf8_lossy(&run.stderr).contains("one of e2e, timeout"));
    let bad = dir.join("bad.toml");
    std::fs::write(&bad, "name = \"x\"\nstates = [\"flying\"]\n").unwrap();
    let run = bywire(&["campaign", path(&bad)]);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(
        !run.status.success() && stderr.contains("bad.toml") && stderr.contains("flying"),
        "{stderr}"
    );
}
