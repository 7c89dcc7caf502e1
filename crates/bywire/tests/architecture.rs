//! ARCHITECTURE.md stays short and true: at most 350 lines, and every crate, path, type and
//! function it names in backticks exists in the tree.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// Every `.rs` file under `dir`, as text.
fn sources(dir: &Path, into: &mut Vec<String>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            sources(&path, into);
        } else if path.extension().is_some_and(|e| e == "rs") {
            into.push(std::fs::read_to_string(&path).unwrap());
        }
    }
}

/// The spans between backticks, outside fenced code blocks.
fn quoted(text: &str) -> Vec<String> {
    let mut names = Vec::new();
    let mut fenced = false;
    for line in text.lines() {
        if line.starts_with("```") {
            fenced = !fenced;
            continue;
        }
        if fenced {
            continue;
        }
        names.extend(line.split('`').skip(1).step_by(2).map(str::to_string));
    }
    names
}

fn is_camel_case(name: &str) -> bool {
    let mut chars = name.chars();
    chars.next().is_some_and(|c| c.is_ascii_uppercase())
        && chars.next().is_some_and(|c| c.is_ascii_lowercase())
        && name.chars().all(|c| c.is_ascii_alphanumeric())
}

#[test]
fn architecture_md_is_short_and_names_only_what_exists() {
    let root = root();
    let text = std::fs::read_to_string(root.join("ARCHITECTURE.md")).unwrap();
    let lines = text.lines().count();
    assert!(
        lines <= 350,
        "ARCHITECTURE.md has {lines} lines (at most 350)"
    );
    let mut code = Vec::new();
    sources(&root.join("crates"), &mut code);
    let declared = |keyword: &[&str], name: &str| {
        code.iter().any(|file| {
            keyword.iter().any(|k| {
                file.contains(&format!("{k} {name} "))
                    || file.contains(&format!("{k} {name}<"))
                    || file.contains(&format!("{k} {name}("))
                    || file.contains(&format!("{k} {name};"))
                    || file.contains(&format!("{k} {name}:"))
            })
        })
    };
    let mut missing = Vec::new();
    let mut checked = 0;
    for name in quoted(&text) {
        let last = name.rsplit("::").next().unwrap_or(&name);
        let exists = if name.contains('/') && !name.contains([' ', '=']) {
            // A path in the tree (or beside it, for the shared design documents).
            root.join(&name).exists()
        } else if name.starts_with("bywire-") || name == "bywire" {
            root.join("crates").join(&name).is_dir()
        } else if is_camel_case(last) {
            declared(&["pub struct", "pub enum", "pub trait", "pub type"], last)
        } else if last.contains('_')
            && last.chars().all(|c| c.is_ascii_lowercase() || c == '_')
            && last != "no_std"
        {
            declared(&["fn", "mod"], last)
        } else {
            continue;
        };
        checked += 1;
        if !exists {
            missing.push(name);
        }
    }
    assert!(checked > 40, "only {checked} names checked");
    assert!(
        missing.is_empty(),
        "ARCHITECTURE.md names what does not exist: {missing:?}"
    );
}
