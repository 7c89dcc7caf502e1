//! The lint table (`requirements/lints.toml`) and the lints the workspace denies
//! (`[workspace.lints]` in Cargo.toml) say the same, every safety crate takes them, and the
//! table is written to `target/evidence/lints.md` for the evidence report.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct Table {
    lint: Vec<Lint>,
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct Lint {
    name: String,
    level: String,
    rule: String,
}

/// The crates whose code is on a control path or decides safety.
const SAFETY_CRATES: [&str; 6] = [
    "bywire-core",
    "bywire-vehicle",
    "bywire-secoc",
    "bywire-canopen",
    "bywire-tug",
    "bywire-control",
];

#[test]
fn the_lint_table_is_the_lints_the_workspace_denies_on_every_safety_crate() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let table: Table =
        toml::from_str(&std::fs::read_to_string(root.join("requirements/lints.toml")).unwrap())
            .unwrap();
    let cargo: toml::Table =
        toml::from_str(&std::fs::read_to_string(root.join("Cargo.toml")).unwrap()).unwrap();
    let lints = cargo["workspace"]["lints"].as_table().unwrap();
    let mut denied = BTreeMap::new();
    for (tool, entries) in lints {
        for (name, level) in entries.as_table().unwrap() {
            let name = match tool.as_str() {
                "rust" => name.clone(),
                tool => format!("{tool}::{name}"),
            };
            denied.insert(name, level.as_str().unwrap().to_string());
        }
    }
    let listed: BTreeMap<String, String> = table
        .lint
        .iter()
        .map(|l| (l.name.clone(), l.level.clone()))
        .collect();
    assert_eq!(listed.len(), table.lint.len(), "a lint listed twice");
    assert_eq!(
        listed, denied,
        "requirements/lints.toml and Cargo.toml differ"
    );
    for l in &table.lint {
        assert!(
            ["deny", "forbid"].contains(&l.level.as_str()) && l.rule.len() > 20,
            "{}",
            l.name
        );
    }
    for krate in SAFETY_CRATES {
        let manifest: toml::Table = toml::from_str(
            &std::fs::read_to_string(root.join("crates").join(krate).join("Cargo.toml")).unwrap(),
        )
        .unwrap();
        let takes = manifest
            .get("lints")
            .and_then(|l| l.get("workspace"))
            .and_then(toml::Value::as_bool);
        assert_eq!(
            takes,
            Some(true),
            "{krate} does not take the workspace's lints"
        );
    }
    let mut md = String::from(
        "# Lint table\n\nThe lints the safety crates deny, each with the coding rule it stands \
         for (from `requirements/lints.toml`, checked against Cargo.toml).\n\n\
         | lint | level | rule |\n|---|---|---|\n",
    );
    for l in &table.lint {
        let _ = writeln!(md, "| `{}` | {} | {} |", l.name, l.level, l.rule);
    }
    let _ = writeln!(md, "\nCrates: {}.", SAFETY_CRATES.join(", "));
    let out = root.join("target/evidence");
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(out.join("lints.md"), md).unwrap();
}
