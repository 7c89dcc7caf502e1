//! Traceability: every requirement in `requirements/requirements.toml` is verified by at least
//! one test that names it (`/// Verifies: REQ-…` on the test) or a campaign cell (a fault of
//! `campaigns/*.toml` naming it), every id a test or a fault names is a requirement, and the
//! matrix (requirement → its tests and cells, the cells' results of this run) is written to
//! `target/traceability.md` for each run to keep.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

#[derive(serde::Deserialize)]
struct File {
    requirement: Vec<Requirement>,
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct Requirement {
    id: String,
    text: String,
    source: String,
    method: String,
}

/// Every `.rs` file under `dir`.
fn sources(dir: &Path, into: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            if path.file_name().is_some_and(|n| n != "target") {
                sources(&path, into);
            }
        } else if path.extension().is_some_and(|e| e == "rs") {
            into.push(path);
        }
    }
}

/// Each test that names requirements: (its ids, "crate/path::name").
fn verifying_tests(root: &Path) -> Vec<(Vec<String>, String)> {
    let mut files = Vec::new();
    sources(&root.join("crates"), &mut files);
    files.sort();
    let mut found = Vec::new();
    for file in files {
        let text = std::fs::read_to_string(&file).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        for (i, line) in lines.iter().enumerate() {
            let Some(ids) = line.trim().strip_prefix("/// Verifies: ") else {
                continue;
            };
            let ids: Vec<String> = ids
                .trim_end_matches('.')
                .split(',')
                .map(|id| id.trim().to_string())
                .collect();
            // The test it documents: a #[test] and its fn within the next few lines.
            let after = lines.iter().skip(i + 1).take(6);
            let (mut test, mut name) = (false, None);
            for next in after {
                test |= next.trim() == "#[test]";
                if let Some(rest) = next.trim().split("fn ").nth(1) {
                    name = rest.split('(').next().map(str::to_string);
                    break;
                }
            }
            let place = file.strip_prefix(root).unwrap().display().to_string();
            let name = name.unwrap_or_else(|| panic!("{place}:{}: Verifies names no fn", i + 1));
            assert!(test, "{place}:{}: {name} is not a #[test]", i + 1);
            found.push((ids, format!("{place}::{name}")));
        }
    }
    found
}

#[test]
fn every_requirement_is_verified_by_a_test_that_names_it() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let text = std::fs::read_to_string(root.join("requirements/requirements.toml")).unwrap();
    let file: File = toml::from_str(&text).unwrap();
    let mut matrix: BTreeMap<&str, Vec<String>> = BTreeMap::new();
    for r in &file.requirement {
        assert!(
            matrix.insert(r.id.as_str(), Vec::new()).is_none(),
            "{} twice",
            r.id
        );
        assert!(
            ["test", "simulation", "analysis", "interop"].contains(&r.method.as_str()),
            "{}: method '{}'",
            r.id,
            r.method
        );
        assert!(!r.text.is_empty() && !r.source.is_empty(), "{}", r.id);
    }
    for (ids, test) in verifying_tests(&root) {
        for id in ids {
            matrix
                .get_mut(id.as_str())
                .unwrap_or_else(|| panic!("{test} verifies {id}, which is no requirement"))
                .push(test.clone());
        }
    }
    for (ids, cells) in campaign_cells(&root) {
        for id in ids {
            matrix
                .get_mut(id.as_str())
                .unwrap_or_else(|| panic!("{cells} verifies {id}, which is no requirement"))
                .push(cells.clone());
        }
    }
    let mut report = String::from(
        "# Traceability\n\nEach requirement of `requirements/requirements.toml` and the tests \
         that verify it (they name it in their documentation), and the campaign cells that do \
         (their faults name it) with this run's results.\n\n\
         | requirement | source | method | verified by |\n|---|---|---|---|\n",
    );
    for r in &file.requirement {
        let tests = &matrix[r.id.as_str()];
        let _ = writeln!(
            report,
            "| **{}** {} | {} | {} | {} |",
            r.id,
            r.text,
            r.source,
            r.method,
            tests
                .iter()
                .map(|t| match t.starts_with("campaign ") {
                    true => t.clone(),
                    false => format!("`{t}`"),
                })
                .collect::<Vec<_>>()
                .join("<br>")
        );
    }
    let out = root.join("target/traceability.md");
    std::fs::create_dir_all(out.parent().unwrap()).unwrap();
    std::fs::write(&out, report).unwrap();
    let unverified: Vec<&&str> = matrix
        .iter()
        .filter(|(_, tests)| tests.is_empty())
        .map(|(id, _)| id)
        .collect();
    assert!(unverified.is_empty(), "verified by nothing: {unverified:?}");
    assert!(file.requirement.len() >= 20);
}

/// Each campaign's faults that name requirements, run: (their ids, "campaign NAME: fault F,
/// P/E cells passed").
fn campaign_cells(root: &Path) -> Vec<(Vec<String>, String)> {
    use bywire_sim::campaign::{self, Campaign, Verdict};
    let mut files: Vec<PathBuf> = std::fs::read_dir(root.join("campaigns"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    files.sort();
    let mut found = Vec::new();
    for file in files {
        let c = Campaign::load(&file).unwrap();
        let results = campaign::run(&c, 2, Default::default(), &|_| {}).unwrap();
        for f in &c.faults {
            let cells: Vec<_> = results.iter().filter(|r| r.fault == f.name()).collect();
            let executed = cells
                .iter()
                .filter(|r| r.verdict != Verdict::NotApplicable)
                .count();
            let passed = cells.iter().filter(|r| r.verdict == Verdict::Pass).count();
            if executed == 0 {
                continue;
            }
            let name = file.file_name().unwrap().to_string_lossy();
            found.push((
                f.requirements.clone(),
                format!(
                    "campaign {name}: {} ({passed}/{executed} cells passed)",
                    f.name()
                ),
            ));
        }
    }
    found
}
