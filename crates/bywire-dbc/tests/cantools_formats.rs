//! KCD and SYM read as cantools reads them: every KCD and SYM file of cantools' own test data
//! (its source release's `tests/files`, fetched by `scripts/install-test-deps.sh`, or the
//! folder `BYWIRE_CANTOOLS_FILES` names) loaded by both, then compared message by message
//! (identifier, format, length, cycle time, senders, comment), signal by signal (layout,
//! scaling, range, unit, value names, multiplexing) and on 32 random frames of every message
//! (the same values, or both refuse the frame). Where the two differ on purpose, `EXPECTED`
//! says why; any other difference fails.
// Tests fail by panicking.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::Command;

use bywire_dbc::codec::MessageCodec;
use bywire_dbc::{format, Database, Format, Mode, Multiplexing, Signal};
use serde_json::Value as Json;

/// Files where bywire and cantools differ, and why: the file, and how the difference begins.
/// Every entry must still be seen.
const EXPECTED: &[(&str, &str)] = &[
    // A 128-bit signal: cantools decodes it as one big integer; bywire's signals are at most
    // 64 bits (as DBC's), so it skips the signal with a positioned error and sizes the message
    // by the rest.
    ("kcd/message_layout.kcd", "message Message7:"),
    ("kcd/message_layout.kcd", "message Message8:"),
    // cantools refuses the whole file for one signal of length 0; bywire skips that signal
    // with a positioned error and loads the rest.
    ("sym/issue_138.sym", "cantools fails"),
    // cantools reads only version 6.0; bywire reads 5.0 as 6.0 with a warning (their syntax is
    // the same for everything the file uses).
    ("sym/jopp-5.0.sym", "cantools fails"),
];

fn files_dir() -> PathBuf {
    std::env::var_os("BYWIRE_CANTOOLS_FILES").map_or_else(
        || Path::new(env!("CARGO_MANIFEST_DIR")).join("../../target/cantools-files"),
        PathBuf::from,
    )
}

fn number(json: &Json) -> f64 {
    json.as_f64().unwrap_or(0.0)
}

/// A range bound cantools gives, or, where it gives only the other bound, as far as the signal
/// reaches (bywire's reading of a KCD `Value` with one bound; cantools leaves it None).
fn bound(this: &Json, other: &Json, reach: f64) -> f64 {
    if this.is_null() && !other.is_null() {
        reach
    } else {
        number(this)
    }
}

/// The multiplexor values a signal is present for (empty: always).
fn values_of(s: &Signal, all: &BTreeSet<u64>) -> BTreeSet<u64> {
    match (&s.mux_condition, s.multiplexing) {
        (Some(c), _) => c.ranges.iter().flat_map(|&(a, b)| a..=b).collect(),
        (None, Multiplexing::Multiplexed(v) | Multiplexing::MultiplexedMultiplexor(v)) => {
            BTreeSet::from([v])
        }
        // An ordinary signal in a multiplexed message: cantools lists it under every value.
        (None, _) => all.clone(),
    }
}

/// The problems with `ours` against cantools' reading; `overlapping` names the messages whose
/// layout the reader reported (signals overlapping or past the end).
fn compare(ours: &Database, overlapping: &BTreeSet<String>, theirs: &Json) -> Vec<String> {
    let mut problems = Vec::new();
    let messages = theirs["messages"].as_array().unwrap();
    if messages.len() != ours.messages.len() {
        return vec![format!(
            "{} messages, cantools {}",
            ours.messages.len(),
            messages.len()
        )];
    }
    for (m, t) in ours.messages.iter().zip(messages) {
        let name = &m.name;
        let mut senders: Vec<&str> = std::iter::once(m.transmitter.as_str())
            .chain(m.senders.iter().map(String::as_str))
            .filter(|s| *s != "Vector__XXX")
            .collect();
        senders.dedup();
        let cycle = ours.cycle_time(m).map(|d| d.as_millis() as f64);
        let facts = [
            (m.name == t["name"].as_str().unwrap(), "name"),
            (u64::from(m.id) == t["frame_id"].as_u64().unwrap(), "id"),
            (m.extended == t["extended"].as_bool().unwrap(), "format"),
            (u64::from(m.size) == t["length"].as_u64().unwrap(), "length"),
            (cycle == t["cycle_time"].as_f64(), "cycle time"),
            (
                senders
                    == t["senders"]
                        .as_array()
                        .unwrap()
                        .iter()
                        .map(|s| s.as_str().unwrap())
                        .collect::<Vec<_>>(),
                "senders",
            ),
            (m.comment.as_deref() == t["comment"].as_str(), "comment"),
        ];
        for (same, what) in facts {
            if !same {
                problems.push(format!("message {name}: {what}"));
            }
        }
        let all: BTreeSet<u64> = m
            .signals
            .iter()
            .flat_map(|s| values_of(s, &BTreeSet::new()))
            .collect();
        let mut their_groups: BTreeMap<&str, BTreeSet<u64>> = BTreeMap::new();
        for ts in t["signals"].as_array().unwrap() {
            let sname = ts["name"].as_str().unwrap();
            their_groups.entry(sname).or_default().extend(
                ts["multiplexer_ids"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|v| v.as_u64().unwrap()),
            );
            let Some(s) = m.signal(sname) else {
                problems.push(format!("message {name}: no signal {sname}"));
                continue;
            };
            let choices: BTreeMap<String, String> = s
                .value_descriptions
                .iter()
                .map(|(v, d)| (v.to_string(), d.clone()))
                .collect();
            let theirs_choices: BTreeMap<String, String> = ts["choices"]
                .as_object()
                .unwrap()
                .iter()
                .map(|(k, v)| (k.clone(), v.as_str().unwrap().to_string()))
                .collect();
            let reach = s.reachable_range().unwrap_or((f64::MIN, f64::MAX));
            let facts = [
                (
                    u64::from(s.start_bit) == ts["start"].as_u64().unwrap(),
                    "start",
                ),
                (
                    u64::from(s.length) == ts["length"].as_u64().unwrap(),
                    "length",
                ),
                (
                    (s.byte_order == bywire_dbc::ByteOrder::BigEndian)
                        == ts["big_endian"].as_bool().unwrap(),
                    "byte order",
                ),
                (
                    matches!(
                        s.value_type,
                        bywire_dbc::ValueType::Integer { signed: true }
                    ) == ts["signed"].as_bool().unwrap(),
                    "sign",
                ),
                (
                    !matches!(s.value_type, bywire_dbc::ValueType::Integer { .. })
                        == ts["float"].as_bool().unwrap(),
                    "float",
                ),
                (s.factor.as_f64() == number(&ts["scale"]), "scale"),
                (s.offset.as_f64() == number(&ts["offset"]), "offset"),
                (
                    s.minimum.as_f64() == bound(&ts["minimum"], &ts["maximum"], reach.0),
                    "minimum",
                ),
                (
                    s.maximum.as_f64() == bound(&ts["maximum"], &ts["minimum"], reach.1),
                    "maximum",
                ),
                (s.unit == ts["unit"].as_str().unwrap(), "unit"),
                (choices == theirs_choices, "choices"),
                (
                    (s.multiplexing == Multiplexing::Multiplexor)
                        == ts["multiplexer"].as_bool().unwrap(),
                    "multiplexor",
                ),
            ];
            for (same, what) in facts {
                if !same {
                    problems.push(format!("message {name} signal {sname}: {what}"));
                }
            }
        }
        let none = BTreeSet::new();
        for (sname, groups) in &their_groups {
            let ours_groups: BTreeSet<u64> = m
                .signals
                .iter()
                .filter(|s| s.name == *sname)
                .flat_map(|s| values_of(s, if groups.is_empty() { &none } else { &all }))
                .collect();
            if &ours_groups != groups {
                problems.push(format!(
                    "message {name} signal {sname}: multiplexed by {ours_groups:?}, cantools {groups:?}"
                ));
            }
        }
        let codec = MessageCodec::new(m);
        for frame in t["frames"].as_array().unwrap() {
            let data: Vec<u8> = (0..frame[0].as_str().unwrap().len() / 2)
                .map(|i| {
                    u8::from_str_radix(&frame[0].as_str().unwrap()[2 * i..2 * i + 2], 16).unwrap()
                })
                .collect();
            let mut out = vec![None; m.signals.len()];
            let ours_values: Option<BTreeMap<String, u64>> =
                codec.decode(&data, &mut out).ok().map(|()| {
                    m.signals
                        .iter()
                        .zip(&out)
                        .filter_map(|(s, d)| {
                            Some((s.name.clone(), d.as_ref()?.physical.as_f64().to_bits()))
                        })
                        .collect()
                });
            let theirs_values: Option<BTreeMap<String, u64>> = frame[1].as_object().map(|o| {
                o.iter()
                    .map(|(k, v)| (k.clone(), v.as_f64().unwrap().to_bits()))
                    .collect()
            });
            // cantools refuses every frame of a message whose signals overlap or run past its
            // end; bywire decodes each signal from its own bits (and reported the layout).
            if theirs_values.is_none() && overlapping.contains(&m.name) {
                continue;
            }
            if ours_values != theirs_values {
                problems.push(format!(
                    "message {name}: frame {} decodes to {ours_values:?}, cantools {theirs_values:?}",
                    frame[0]
                ));
                break;
            }
        }
    }
    problems
}

#[test]
fn kcd_and_sym_files_read_as_cantools_reads_them() {
    let dir = files_dir();
    assert!(
        dir.join("kcd").is_dir(),
        "{} has no cantools test files: run scripts/install-test-deps.sh",
        dir.display()
    );
    let mut files: Vec<String> = Vec::new();
    for sub in ["kcd", "sym"] {
        for entry in std::fs::read_dir(dir.join(sub)).unwrap() {
            let name = entry.unwrap().file_name().into_string().unwrap();
            files.push(format!("{sub}/{name}"));
        }
    }
    files.sort();
    let oracle = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/oracles/cantools_database.py");
    let output = Command::new("python3")
        .arg(&oracle)
        .args(&files)
        .current_dir(&dir)
        .output()
        .unwrap();
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let mut differences: Vec<(String, String)> = Vec::new();
    let mut compared = 0;
    for line in String::from_utf8(output.stdout).unwrap().lines() {
        let theirs: Json = serde_json::from_str(line).unwrap();
        let file = theirs["file"].as_str().unwrap().to_string();
        let bytes = std::fs::read(dir.join(&file)).unwrap();
        let format = Format::from_path(Path::new(&file)).unwrap();
        let ours = format::load(&bytes, format, Mode::Lenient);
        match (ours, theirs.get("error")) {
            (Ok(_), Some(_)) => differences.push((file, "cantools fails".into())),
            (Err(e), None) => differences.push((file, format!("bywire fails: {e}"))),
            (Err(_), Some(_)) => {}
            (Ok((db, diagnostics)), None) => {
                compared += 1;
                let overlapping: BTreeSet<String> = db
                    .messages
                    .iter()
                    .filter(|m| {
                        let of = format!("of message {}", m.name);
                        diagnostics.iter().any(|d| d.message.contains(&of))
                    })
                    .map(|m| m.name.clone())
                    .collect();
                for problem in compare(&db, &overlapping, &theirs) {
                    differences.push((file.clone(), problem));
                }
            }
        }
    }
    assert!(compared >= 25, "only {compared} files compared");
    let accepted = |(file, problem): &(String, String)| {
        EXPECTED
            .iter()
            .any(|(f, start)| f == file && problem.starts_with(start))
    };
    let unexpected: Vec<&(String, String)> = differences.iter().filter(|d| !accepted(d)).collect();
    assert!(
        unexpected.is_empty(),
        "compared {compared} files: {unexpected:#?}"
    );
    for (file, start) in EXPECTED {
        assert!(
            differences
                .iter()
                .any(|(f, p)| f == file && p.starts_with(start)),
            "{file}: '{start}' is no longer a difference"
        );
    }
}
