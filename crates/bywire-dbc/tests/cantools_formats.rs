//! KCD, SYM, ARXML and CDD read as cantools reads them: every KCD, SYM, ARXML and CDD file of cantools'
//! own test data (its source release's `tests/files`, fetched by
//! `scripts/install-test-deps.sh`, or the folder `BYWIRE_CANTOOLS_FILES` names) and of
//! canmatrix's (shipped in `tests/canmatrix` with its licence) loaded by both, then compared
//! message by message (identifier, format, CAN FD, length, cycle time, senders, comment, a
//! container's PDUs), signal by signal (layout, scaling, range, unit, value names,
//! multiplexing) and on 32 random frames of every message (the same values, or both refuse
//! the frame). Where the two differ on purpose, `EXPECTED` says why; any other difference
//! fails. canmatrix's conversions of one database into each format are also read against each
//! other, which covers the files cantools cannot read.
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
    // A frame of 64 bytes is CAN FD whatever its triggering says; cantools calls it classic
    // CAN because the file names no CAN FD behaviour (and its PDUs of 9 and 10 bytes too).
    (
        "arxml/system-4.2.arxml",
        "message OneToContainThemAll: CAN FD",
    ),
    (
        "arxml/system-4.2.arxml",
        "container OneToContainThemAll: message message1: CAN FD",
    ),
    (
        "arxml/system-4.2.arxml",
        "container OneToContainThemAll: message multiplexed_message: CAN FD",
    ),
    // cantools refuses the whole file for one dangling frame reference, or one linear scaling
    // without its denominator or second numerator; bywire reports each with its position,
    // leaves out the frame (or reads the signal unscaled) and loads the rest.
    (
        "arxml/system-dangling-reference-4.2.arxml",
        "cantools fails",
    ),
    (
        "arxml/system-missing-denominator-4.2.arxml",
        "cantools fails",
    ),
    ("arxml/system-missing-factor-4.2.arxml", "cantools fails"),
    // A data type's byte order code 4321 (neither 12 nor 21): cantools refuses the file;
    // bywire reports it with its position and reads the type as big-endian.
    ("cdd/invalid-bo-example.cdd", "cantools fails"),
    // canmatrix's own test files (`tests/canmatrix`). cantools stops at: a file of compu
    // methods and no frame (a TypeError); a contained PDU without a header ID (an
    // AttributeError; bywire leaves that PDU out with a positioned error); a linear scaling
    // with two denominators; two elements with one path (canmatrix's AUTOSAR 3 writer names a
    // signal's triggering and compu method alike in several places; bywire warns and resolves
    // to the first).
    (
        "canmatrix/files/arxml/ARXMLCompuMethod1.arxml",
        "cantools fails",
    ),
    (
        "canmatrix/files/arxml/ARXMLContainerTest.arxml",
        "cantools fails",
    ),
    (
        "canmatrix/files/arxml/ARXML_min_max.arxml",
        "cantools fails",
    ),
    ("canmatrix/files/arxml/test.arxml", "cantools fails"),
    ("canmatrix/reference/from_kcd/test.arxml", "cantools fails"),
    ("canmatrix/reference/from_sym/test.arxml", "cantools fails"),
    // An AUTOSAR 3 cluster whose channel is a CAN-PHYSICAL-CHANNEL (cantools looks for
    // PHYSICAL-CHANNEL only, and finds no frame).
    (
        "canmatrix/files/arxml/ARXMLSecuredPDUTest.arxml",
        "2 messages, cantools 0",
    ),
    // canmatrix writes SYM 5.0 (cantools reads 6.0 only; bywire reads 5.0 as 6.0).
    ("canmatrix/files/sym/test.sym", "cantools fails"),
    (
        "canmatrix/reference/from_arxml/test_CAN.sym",
        "cantools fails",
    ),
    ("canmatrix/reference/from_dbc/test.sym", "cantools fails"),
    ("canmatrix/reference/from_dbf/test.sym", "cantools fails"),
    ("canmatrix/reference/from_json/test.sym", "cantools fails"),
    (
        "canmatrix/reference/from_kcd/test_test.kcd.sym",
        "cantools fails",
    ),
    // canmatrix's spreadsheet conversions lost the extended flag: 29-bit identifiers on
    // standard frames, which cantools refuses and bywire leaves out with an error each.
    ("canmatrix/reference/from_xls/test.arxml", "cantools fails"),
    ("canmatrix/reference/from_xls/test.kcd", "cantools fails"),
    ("canmatrix/reference/from_xls/test.sym", "cantools fails"),
    ("canmatrix/reference/from_xlsx/test.arxml", "cantools fails"),
    ("canmatrix/reference/from_xlsx/test.kcd", "cantools fails"),
    ("canmatrix/reference/from_xlsx/test.sym", "cantools fails"),
    // A compu method without a category: cantools reads no scaling and no value names;
    // bywire reads the scales it has (canmatrix writes the DBC's scaling and value table this
    // way, and the KCD and SYM it wrote from the same DBC carry them).
    (
        "canmatrix/reference/from_dbc/test.arxml",
        "message FRAME_testFrame1",
    ),
    (
        "canmatrix/reference/from_dbf/test.arxml",
        "message FRAME_testFrame1",
    ),
    (
        "canmatrix/reference/from_json/test.arxml",
        "message FRAME_testFrame1",
    ),
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
            // An empty comment and none are one thing (cantools keeps KCD's `<Notes></Notes>`
            // as "").
            (
                m.comment.as_deref().filter(|c| !c.is_empty())
                    == t["comment"].as_str().filter(|c| !c.is_empty()),
                "comment",
            ),
            (ours.fd_format(m).0 == t["fd"].as_bool().unwrap(), "CAN FD"),
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
            // A name may stand in several multiplexed groups: the signal of this one.
            let their_ids: BTreeSet<u64> = ts["multiplexer_ids"]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_u64().unwrap())
                .collect();
            // A name may also stand twice in one group: the one at the same place.
            let their_start = u32::try_from(ts["start"].as_u64().unwrap()).unwrap();
            let named = || m.signals.iter().filter(|s| s.name == sname);
            let grouped = || named().filter(|s| values_of(s, &BTreeSet::new()) == their_ids);
            let Some(s) = grouped()
                .find(|s| s.start_bit == their_start)
                .or_else(|| grouped().next())
                .or_else(|| named().next())
            else {
                problems.push(format!("message {name}: no signal {sname}"));
                continue;
            };
            let choices: BTreeMap<String, String> = s
                .value_descriptions
                .iter()
                .map(|(v, d)| (v.to_string(), d.clone()))
                .collect();
            // cantools keys an ARXML value name by the float its limits give (`0.0`): the same
            // raw value.
            let theirs_choices: BTreeMap<String, String> = ts["choices"]
                .as_object()
                .unwrap()
                .iter()
                .map(|(k, v)| {
                    let key = match k.parse::<f64>() {
                        Ok(f) if f.fract() == 0.0 => format!("{f:.0}"),
                        _ => k.clone(),
                    };
                    (key, v.as_str().unwrap().to_string())
                })
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
        if t["container"].as_bool().unwrap() {
            let Some(container) = ours.containers.iter().find(|c| &c.message == name) else {
                problems.push(format!("message {name}: not a container"));
                continue;
            };
            let pdus = Database {
                messages: container.pdus.clone(),
                ..ours.clone()
            };
            let contained = serde_json::json!({ "messages": t["contained"] });
            for problem in compare(&pdus, overlapping, &contained) {
                problems.push(format!("container {name}: {problem}"));
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

/// canmatrix's test files (`tests/canmatrix`, shipped packed with its licence), unpacked into
/// a folder that goes when dropped.
fn canmatrix_files() -> tempfile::TempDir {
    let unpacked = tempfile::tempdir().unwrap();
    let archive = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/canmatrix/files.tar.xz");
    let status = Command::new("tar")
        .arg("xJf")
        .arg(&archive)
        .arg("-C")
        .arg(unpacked.path())
        .status()
        .unwrap();
    assert!(status.success());
    unpacked
}

/// Every database file under `dir`'s `subs`, read by bywire and by cantools: the differences
/// (each file named with `prefix`) and how many files both read.
fn differences_in(dir: &Path, subs: &[&str], prefix: &str) -> (Vec<(String, String)>, usize) {
    let mut files: Vec<String> = Vec::new();
    for sub in subs {
        let Ok(entries) = std::fs::read_dir(dir.join(sub)) else {
            continue;
        };
        for entry in entries {
            let name = entry.unwrap().file_name().into_string().unwrap();
            if Format::from_path(Path::new(&name)).is_some() {
                files.push(format!("{sub}/{name}"));
            }
        }
    }
    files.sort();
    let oracle = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/oracles/cantools_database.py");
    let output = Command::new("python3")
        .arg(&oracle)
        .args(&files)
        .current_dir(dir)
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
        let path = theirs["file"].as_str().unwrap().to_string();
        let file = format!("{prefix}{path}");
        let bytes = std::fs::read(dir.join(&path)).unwrap();
        let format = Format::from_path(Path::new(&path)).unwrap();
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
                // A CDD's DIDs are no frames (no CAN FD), and cantools takes a value type's
                // minsz and maxsz (the byte sizes of variable-length values) as their data's
                // range, which bywire does not.
                let cdd = format == Format::Cdd;
                let not_for_dids = |p: &String| {
                    [": CAN FD", ": minimum", ": maximum"]
                        .iter()
                        .any(|end| p.ends_with(end))
                };
                for problem in compare(&db, &overlapping, &theirs) {
                    if !(cdd && not_for_dids(&problem)) {
                        differences.push((file.clone(), problem));
                    }
                }
            }
        }
    }
    (differences, compared)
}

#[test]
fn kcd_sym_and_arxml_files_read_as_cantools_reads_them() {
    let dir = files_dir();
    assert!(
        dir.join("kcd").is_dir(),
        "{} has no cantools test files: run scripts/install-test-deps.sh",
        dir.display()
    );
    let (mut differences, mut compared) = differences_in(&dir, &["kcd", "sym", "arxml", "cdd"], "");
    let unpacked = canmatrix_files();
    for root in ["files", "reference"] {
        let base = unpacked.path().join(root);
        let mut subs: Vec<String> = vec!["kcd".into(), "sym".into(), "arxml".into()];
        for entry in std::fs::read_dir(&base).unwrap() {
            let name = entry.unwrap().file_name().into_string().unwrap();
            if name.starts_with("from_") {
                subs.push(name);
            }
        }
        let subs: Vec<&str> = subs.iter().map(String::as_str).collect();
        let (more, count) = differences_in(&base, &subs, &format!("canmatrix/{root}/"));
        differences.extend(more);
        compared += count;
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

/// canmatrix's conversions of one database into several formats (its `tests/reference`), read
/// by bywire: every signal both files have lies at the same bits with the same scaling. This
/// checks bywire's ARXML, KCD and SYM readers against canmatrix's writers where cantools cannot
/// read the files (see `EXPECTED`). Signedness is not compared: canmatrix's AUTOSAR 3 writer
/// does not write it.
#[test]
fn canmatrix_conversions_of_one_database_agree() {
    let unpacked = canmatrix_files();
    // The xls family is left out: canmatrix's converter lost its extended identifiers (every
    // file has 29-bit identifiers on standard frames, which bywire and cantools refuse).
    let families: &[&[&str]] = &[
        &[
            "files/sym/test.sym",
            "reference/from_sym/test.arxml",
            "reference/from_sym/test.kcd",
        ],
        &[
            "files/kcd/test.kcd",
            "reference/from_kcd/test.arxml",
            "reference/from_kcd/test_test.kcd.sym",
        ],
        &[
            "files/arxml/test.arxml",
            "reference/from_arxml/test.kcd",
            "reference/from_arxml/test_CAN.sym",
        ],
        &[
            "reference/from_dbc/test.arxml",
            "reference/from_dbc/test.kcd",
            "reference/from_dbc/test.sym",
        ],
        &[
            "reference/from_json/test.arxml",
            "reference/from_json/test.kcd",
            "reference/from_json/test.sym",
        ],
    ];
    let load = |file: &str| {
        let path = unpacked.path().join(file);
        let bytes = std::fs::read(&path).unwrap();
        let format = Format::from_path(&path).unwrap();
        format::load(&bytes, format, Mode::Lenient)
            .unwrap_or_else(|e| panic!("{file}: {e}"))
            .0
    };
    let mut problems: Vec<String> = Vec::new();
    let mut compared = 0;
    for family in families {
        let source = load(family[0]);
        assert!(!source.messages.is_empty(), "{}", family[0]);
        for other_file in &family[1..] {
            let other = load(other_file);
            for m in &source.messages {
                let Some(o) = other.message(m.id, m.extended) else {
                    problems.push(format!("{other_file}: no message {} ({:#x})", m.name, m.id));
                    continue;
                };
                for s in &m.signals {
                    let named = || {
                        o.signals
                            .iter()
                            .filter(|t| t.name == s.name && t.multiplexing == s.multiplexing)
                    };
                    let Some(t) = named()
                        .find(|t| t.start_bit == s.start_bit)
                        .or_else(|| named().next())
                    else {
                        continue;
                    };
                    compared += 1;
                    let layout = |x: &Signal| (x.start_bit, x.length, x.byte_order);
                    let scaling = |x: &Signal| (x.factor.as_f64(), x.offset.as_f64());
                    if layout(s) != layout(t) || scaling(s) != scaling(t) {
                        problems.push(format!(
                            "{other_file}: message {} signal {}: {:?} {:?} in {}, {:?} {:?}",
                            m.name,
                            s.name,
                            layout(s),
                            scaling(s),
                            family[0],
                            layout(t),
                            scaling(t),
                        ));
                    }
                }
            }
        }
    }
    assert!(compared > 500, "only {compared} signals compared");
    assert!(problems.is_empty(), "{problems:#?}");
}
