//! A campaign's results as files: `junit.xml` (one test case per cell, for CI), `cells.json`
//! (every cell's inputs and observations), and the coverage matrix — fault classes against
//! mechanisms, per profile — as `report.md` and `report.html`.

use std::fmt::Write as _;
use std::path::Path;

use bywire_vehicle::mechanism::{Mechanism, Mechanisms};

use super::{Campaign, CellResult, Verdict};

/// Counts of a set of cells.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Tally {
    /// Cells run.
    pub executed: usize,
    /// Of which passed.
    pub passed: usize,
    /// Of which failed.
    pub failed: usize,
    /// Cells that do not apply.
    pub not_applicable: usize,
}

impl Tally {
    /// The tally of `cells`.
    pub fn of<'a>(cells: impl IntoIterator<Item = &'a CellResult>) -> Tally {
        let mut t = Tally::default();
        for c in cells {
            match c.verdict {
                Verdict::Pass => {
                    t.executed += 1;
                    t.passed += 1;
                }
                Verdict::Fail => {
                    t.executed += 1;
                    t.failed += 1;
                }
                Verdict::NotApplicable => t.not_applicable += 1,
            }
        }
        t
    }
}

/// The mechanisms of `disabled` whose removal no cell noticed: a failed cell that expected
/// it. (With several switched off at once, a failure is credited to the one it expected.)
pub fn unnoticed(results: &[CellResult], disabled: Mechanisms) -> Vec<Mechanism> {
    let alone = disabled.iter().count() == 1;
    disabled
        .iter()
        .filter(|m| {
            !with_verdict(results, Verdict::Fail).any(|c| alone || c.expected.mechanism == Some(*m))
        })
        .collect()
}

/// The cells with `verdict`.
fn with_verdict(results: &[CellResult], verdict: Verdict) -> impl Iterator<Item = &CellResult> {
    results.iter().filter(move |c| c.verdict == verdict)
}

/// Write the four files into `dir` (created if need be); each is written whole to a
/// temporary name and renamed, so a reader never sees half a report.
pub fn write(
    dir: &Path,
    campaign: &Campaign,
    results: &[CellResult],
    disabled: Mechanisms,
    wall_seconds: f64,
) -> std::io::Result<()> {
    std::fs::create_dir_all(dir)?;
    let json = serde_json::to_string_pretty(results).map_err(std::io::Error::other)?;
    let files = [
        ("junit.xml", junit(campaign, results, wall_seconds)),
        ("cells.json", json + "\n"),
        (
            "report.md",
            markdown(campaign, results, disabled, wall_seconds),
        ),
        (
            "report.html",
            html(campaign, results, disabled, wall_seconds),
        ),
    ];
    for (name, text) in files {
        let tmp = dir.join(format!(".{name}.tmp"));
        std::fs::write(&tmp, text)?;
        std::fs::rename(&tmp, dir.join(name))?;
    }
    Ok(())
}

fn xml_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// JUnit XML: a test suite per profile, a test case per cell (`profile/state/fault/
/// mechanism`), failures with their reason, cells that do not apply as skipped.
pub fn junit(campaign: &Campaign, results: &[CellResult], wall_seconds: f64) -> String {
    let all = Tally::of(results);
    let mut out = String::from("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n");
    let _ = writeln!(
        out,
        "<testsuites name=\"{}\" tests=\"{}\" failures=\"{}\" skipped=\"{}\" time=\"{wall_seconds:.3}\">",
        xml_escape(&campaign.name),
        results.len(),
        all.failed,
        all.not_applicable
    );
    for profile in campaign.profiles.iter().map(|p| p.label()) {
        let cells: Vec<&CellResult> = results.iter().filter(|c| c.profile == profile).collect();
        let t = Tally::of(cells.iter().copied());
        let time: f64 = cells.iter().map(|c| c.wall_seconds).sum();
        let _ = writeln!(
            out,
            "  <testsuite name=\"{}/{}\" tests=\"{}\" failures=\"{}\" skipped=\"{}\" time=\"{time:.3}\">",
            xml_escape(&campaign.name),
            xml_escape(profile),
            cells.len(),
            t.failed,
            t.not_applicable
        );
        for c in cells {
            let _ = write!(
                out,
                "    <testcase classname=\"{}\" name=\"{}\" time=\"{:.3}\"",
                xml_escape(&campaign.name),
                xml_escape(&c.name),
                c.wall_seconds
            );
            match c.verdict {
                Verdict::Pass => out.push_str("/>\n"),
                Verdict::Fail => {
                    let _ = writeln!(
                        out,
                        ">\n      <failure message=\"{}\"/>\n    </testcase>",
                        xml_escape(&c.why)
                    );
                }
                Verdict::NotApplicable => {
                    let _ = writeln!(
                        out,
                        ">\n      <skipped message=\"not applicable: {}\"/>\n    </testcase>",
                        xml_escape(&c.why)
                    );
                }
            }
        }
        out.push_str("  </testsuite>\n");
    }
    out.push_str("</testsuites>\n");
    out
}

/// The matrix's columns: no mechanism needed (a fault the vehicle tolerates), then each.
fn columns() -> impl Iterator<Item = Option<Mechanism>> {
    core::iter::once(None).chain(Mechanism::ALL.into_iter().map(Some))
}

/// One entry of the matrix: a fault class's cells against one mechanism (`None`: those
/// expecting none).
fn entry(cells: &[&CellResult], m: Option<Mechanism>) -> (String, &'static str) {
    let expecting: Vec<&CellResult> = cells
        .iter()
        .copied()
        .filter(|c| c.expected.mechanism == m)
        .collect();
    let t = Tally::of(expecting.iter().copied());
    if t.executed > 0 {
        let text = format!("{}/{}", t.passed, t.executed);
        return match t.failed {
            0 => (text, "pass"),
            _ => (format!("{text} ({} failed)", t.failed), "fail"),
        };
    }
    if t.not_applicable > 0 {
        return ("n/a".into(), "na");
    }
    let also = cells
        .iter()
        .filter(|c| m.is_some() && c.detected_by.iter().any(|d| d.mechanism == m))
        .count();
    match also {
        0 => ("·".into(), "none"),
        n => (format!("also {n}"), "also"),
    }
}

/// A row of the matrix: the fault's name, then per column the text and its style.
type Row = (String, Vec<(String, &'static str)>);

/// The matrix per profile: rows the fault classes, columns the mechanisms.
fn matrix(campaign: &Campaign, results: &[CellResult]) -> Vec<(String, Vec<Row>)> {
    campaign
        .profiles
        .iter()
        .map(|p| {
            let rows = campaign
                .faults
                .iter()
                .map(|f| {
                    let cells: Vec<&CellResult> = results
                        .iter()
                        .filter(|c| c.profile == p.label() && c.fault == f.name())
                        .collect();
                    let entries = columns().map(|m| entry(&cells, m)).collect();
                    (f.name().to_string(), entries)
                })
                .collect();
            (p.label().to_string(), rows)
        })
        .collect()
}

fn summary_lines(results: &[CellResult], disabled: Mechanisms, wall_seconds: f64) -> Vec<String> {
    let t = Tally::of(results);
    let mut lines = vec![format!(
        "{} cells: {} executed, {} passed, {} failed, {} not applicable; {wall_seconds:.1} s",
        results.len(),
        t.executed,
        t.passed,
        t.failed,
        t.not_applicable
    )];
    if !disabled.is_empty() {
        let names: Vec<&str> = disabled.iter().map(Mechanism::name).collect();
        lines.push(format!(
            "Switched off in the vehicle's software: {}; {} cells failed for it.",
            names.join(", "),
            t.failed
        ));
        for m in unnoticed(results, disabled) {
            lines.push(format!(
                "No cell failed without {m}: this campaign does not test it."
            ));
        }
    }
    lines
}

/// The Markdown report.
pub fn markdown(
    campaign: &Campaign,
    results: &[CellResult],
    disabled: Mechanisms,
    wall_seconds: f64,
) -> String {
    let mut out = format!("# Campaign {}\n\n", campaign.name);
    for line in summary_lines(results, disabled, wall_seconds) {
        let _ = writeln!(out, "{line}\n");
    }
    out.push_str(
        "Each entry: cells passed / executed where the mechanism is the one expected to detect \
         the fault (`(none)`: where the vehicle must tolerate it); `n/a` where every such cell does not apply (the reason is in cells.json); \
         `also N` where it is not the expected mechanism but noticed the fault in N cells; `·` \
         where it played no part.\n",
    );
    let names: Vec<&str> = columns()
        .map(|m| m.map_or("(none)", Mechanism::name))
        .collect();
    for (profile, rows) in matrix(campaign, results) {
        let _ = write!(
            out,
            "\n## {profile}\n\n| fault | {} |\n|---|",
            names.join(" | ")
        );
        out.push_str(&"---|".repeat(names.len()));
        out.push('\n');
        for (fault, entries) in rows {
            let cells: Vec<&str> = entries.iter().map(|(t, _)| t.as_str()).collect();
            let _ = writeln!(out, "| {fault} | {} |", cells.join(" | "));
        }
    }
    let failed: Vec<&CellResult> = with_verdict(results, Verdict::Fail).collect();
    if !failed.is_empty() {
        out.push_str("\n## Failed cells\n\n");
        for c in failed {
            let _ = writeln!(out, "- `{}`: {}", c.name, c.why);
        }
    }
    // Each profile's fault and reason once (the states of one fault share theirs).
    let reasons: std::collections::BTreeSet<(String, &str)> =
        with_verdict(results, Verdict::NotApplicable)
            .map(|c| (format!("{}/{}", c.profile, c.fault), c.why.as_str()))
            .collect();
    if !reasons.is_empty() {
        out.push_str("\n## Not applicable\n\n");
        for (what, why) in reasons {
            let _ = writeln!(out, "- {what}: {why}");
        }
    }
    out
}

/// The HTML report: the same, self-contained, coloured.
pub fn html(
    campaign: &Campaign,
    results: &[CellResult],
    disabled: Mechanisms,
    wall_seconds: f64,
) -> String {
    let mut out = format!(
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>Campaign {0}</title>\n<style>\nbody{{font-family:sans-serif;margin:2em}}table{{border-collapse:collapse;margin-bottom:2em}}th,td{{border:1px solid #999;padding:.25em .5em;text-align:center}}td:first-child{{text-align:left}}.pass{{background:#c8f0c8}}.fail{{background:#f4b4b4}}.na{{background:#e8e8e8}}.also{{background:#eef6ff}}\n</style></head><body>\n<h1>Campaign {0}</h1>\n",
        xml_escape(&campaign.name)
    );
    for line in summary_lines(results, disabled, wall_seconds) {
        let _ = writeln!(out, "<p>{}</p>", xml_escape(&line));
    }
    for (profile, rows) in matrix(campaign, results) {
        let _ = write!(
            out,
            "<h2>{}</h2>\n<table><tr><th>fault</th>",
            xml_escape(&profile)
        );
        for m in columns() {
            let _ = write!(out, "<th>{}</th>", m.map_or("(none)", Mechanism::name));
        }
        out.push_str("</tr>\n");
        for (fault, entries) in rows {
            let _ = write!(out, "<tr><td>{}</td>", xml_escape(&fault));
            for (text, class) in entries {
                let _ = write!(out, "<td class=\"{class}\">{}</td>", xml_escape(&text));
            }
            out.push_str("</tr>\n");
        }
        out.push_str("</table>\n");
    }
    let failed: Vec<&CellResult> = with_verdict(results, Verdict::Fail).collect();
    if !failed.is_empty() {
        out.push_str("<h2>Failed cells</h2>\n<ul>\n");
        for c in failed {
            let _ = writeln!(
                out,
                "<li><code>{}</code>: {}</li>",
                xml_escape(&c.name),
                xml_escape(&c.why)
            );
        }
        out.push_str("</ul>\n");
    }
    out.push_str("</body></html>\n");
    out
}
