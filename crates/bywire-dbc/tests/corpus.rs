//! The real-world corpus in `../shared/corpus/`, one test case per DBC file:
//! - `load/<file>`: lenient loading keeps every `BO_` and `SG_` statement of the file;
//! - `roundtrip/<file>`: load → write → load gives an equal database;
//! - `json/<file>`: load → JSON → database gives an equal database;
//! - `vectors/<file>`: decoding agrees with every cantools vector of the file (same signals,
//!   same values, floats bit-exact, same multiplexer selection) and re-encoding gives the
//!   vector's `reencoded_hex`.
//! - `columns/<file>`: every message decoded a column at a time gives, frame for frame, the
//!   values decoding frame by frame gives (what Arrow tables are built from).
//! - `kcd/<file>`, `sym/<file>`: the database written as KCD (SYM) reads back as exactly what
//!   that format can say (`format::expressible`), which then writes to DBC and reads back
//!   equal; every message decodes 64 random frames to the same values as the original unless
//!   an omission the writer listed names it. `BYWIRE_OMISSIONS=1` prints each file's omissions.
//! - `strict/<file>` for the 46 files cantools rejects even leniently: strict mode rejects them
//!   with a position.
//!
//! Disagreement classes accepted, with the reason:
//! 1. cantools refuses a whole message with "unpacking failed" when its signals overlap or run
//!    past the end (its non-strict mode still builds the codec). bywire decodes each signal
//!    from its own bits, and signals past the end as absent; those vectors are compared with
//!    cantools' own per-signal decode (`decoded_per_signal`), which must agree exactly. For a
//!    multiplexed message cantools records no per-signal decode, so there is nothing to
//!    compare; those vectors are counted and skipped (vw_pq.dbc's Gate_Komf_1 only).
//! 2. A multiplexer indicator written `m` with no value (vw_pq.dbc, Motor_2): bywire reads it as
//!    the multiplexor `M`, as the `m1`..`m3` signals that depend on it show was meant; cantools
//!    ignores it and never decodes those signals. bywire's extra signals are the multiplexed
//!    ones only; every signal cantools decodes must agree.
//! 3. Nothing else: every other vector must agree exactly.
// Tests fail by panicking; helpers outside #[test] functions may unwrap too.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use std::collections::{BTreeMap, BTreeSet};
use std::io::BufRead;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use bywire_dbc::codec::{DecodeError, Decoded, MessageCodec, Value};
use bywire_dbc::{parse, parse_str, write, Database, Mode};
use libtest_mimic::{Arguments, Failed, Trial};
use serde_json::Value as Json;

fn corpus() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/corpus")
}

fn load(path: &Path) -> Database {
    parse(&std::fs::read(path).unwrap(), Mode::Lenient)
        .unwrap()
        .0
}

fn statements(text: &str, keyword: &str) -> usize {
    text.lines()
        .filter(|l| l.trim_start().starts_with(keyword))
        .count()
}

fn check_load(path: &Path) -> Result<(), Failed> {
    let bytes = std::fs::read(path).unwrap();
    let (db, _) = parse(&bytes, Mode::Lenient).map_err(|e| e.to_string())?;
    let text = String::from_utf8_lossy(&bytes);
    let signals: usize = db.messages.iter().map(|m| m.signals.len()).sum();
    if statements(&text, "BO_ ") != db.messages.len() || statements(&text, "SG_ ") != signals {
        return Err(format!(
            "kept {} of {} messages, {signals} of {} signals",
            db.messages.len(),
            statements(&text, "BO_ "),
            statements(&text, "SG_ ")
        )
        .into());
    }
    Ok(())
}

fn check_json(path: &Path) -> Result<(), Failed> {
    let db = load(path);
    let json = serde_json::to_string(&db).map_err(|e| e.to_string())?;
    let again: Database = serde_json::from_str(&json).map_err(|e| e.to_string())?;
    if again != db {
        return Err("database differs after DBC -> JSON -> database".into());
    }
    Ok(())
}

/// The schedule analysis takes every file: each message analysed or left out with a reason,
/// in priority order, every bound at least the message's jitter and frame.
fn check_schedule(path: &Path) -> Result<(), Failed> {
    use bywire_dbc::schedule::{analyse, Options};
    let db = load(path);
    for nominal in [125_000, 500_000] {
        let options = Options {
            rates: bywire_core::busload::Bitrates {
                nominal,
                data: Some(2_000_000),
            },
            jitter: std::time::Duration::from_micros(100),
        };
        let schedule = analyse(&db, |_| true, options);
        if schedule.messages.len() + schedule.skipped.len() != db.messages.len() {
            return Err("a message was neither analysed nor left out".into());
        }
        if !schedule.messages.windows(2).all(|w| w[0].id <= w[1].id) {
            return Err("not in priority order".into());
        }
        if !(schedule.utilisation.is_finite() && schedule.utilisation >= 0.0) {
            return Err(format!("utilisation {}", schedule.utilisation).into());
        }
        for m in &schedule.messages {
            if let Ok(r) = m.outcome {
                if r.worst_ns < m.frame_ns + m.jitter_ns || r.instances == 0 {
                    return Err(format!("{}: {r:?}", m.name).into());
                }
            }
        }
        if schedule.skipped.iter().any(|s| s.reason.is_empty()) {
            return Err("left out without a reason".into());
        }
    }
    Ok(())
}

fn check_roundtrip(path: &Path) -> Result<(), Failed> {
    let db = load(path);
    let written = write(&db);
    let (again, diags) = parse_str(&written, Mode::Lenient).map_err(|e| e.to_string())?;
    if again != db {
        return Err(format!(
            "reloaded database differs; {} diagnostics on reload",
            diags.len()
        )
        .into());
    }
    Ok(())
}

/// The database through `format` and back: what the format can say, nothing else lost.
fn check_format(path: &Path, format: bywire_dbc::Format) -> Result<(), Failed> {
    use bywire_dbc::format;
    let db = load(path);
    let (expected, omissions) = format::expressible(&db, format);
    let (text, listed) = format::write(&db, format);
    if listed != omissions {
        return Err("the writer listed other omissions than the reduction".into());
    }
    if std::env::var_os("BYWIRE_OMISSIONS").is_some() && !omissions.is_empty() {
        let list: Vec<String> = omissions.iter().map(ToString::to_string).collect();
        eprintln!("{} as {format}: {}", path.display(), list.join("; "));
    }
    let (back, _) = format::load(text.as_bytes(), format, Mode::Lenient)
        .map_err(|e| format!("written {format} does not read: {e}"))?;
    if back != expected {
        let first = back
            .messages
            .iter()
            .zip(&expected.messages)
            .find(|(a, b)| a != b)
            .map(|(a, b)| format!("{a:#?}\nexpected\n{b:#?}"))
            .unwrap_or_else(|| "outside the messages".into());
        return Err(format!("read back differs from what {format} can say: {first}").into());
    }
    // DBC names a signal's float type and value names by its name: of two signals one name
    // in a message, it cannot say which is which.
    let twice = back.messages.iter().any(|m| {
        m.signals
            .iter()
            .enumerate()
            .any(|(i, s)| m.signals[..i].iter().any(|o| o.name == s.name))
    });
    let (again, _) = parse_str(&write(&back), Mode::Lenient).map_err(|e| e.to_string())?;
    if again != back && !twice {
        return Err(format!("{format} → DBC → database differs").into());
    }
    let mut seed = 0x9E37_79B9_7F4A_7C15_u64;
    for original in &db.messages {
        let named = |what: &str| what.contains(&format!("message {}", original.name));
        let kept = expected
            .messages
            .iter()
            .any(|m| m.id == original.id && m.extended == original.extended);
        if omissions.iter().any(|o| named(&o.what)) || !kept {
            continue;
        }
        let Some(converted) = back
            .messages
            .iter()
            .find(|m| m.id == original.id && m.extended == original.extended)
        else {
            return Err(format!("message {} is missing", original.name).into());
        };
        let (a, b) = (MessageCodec::new(original), MessageCodec::new(converted));
        for _ in 0..64 {
            let frame: Vec<u8> = (0..original.size.min(64))
                .map(|_| {
                    seed ^= seed << 13;
                    seed ^= seed >> 7;
                    seed ^= seed << 17;
                    seed.to_le_bytes()[0]
                })
                .collect();
            if decoded_by_name(&a, original, &frame) != decoded_by_name(&b, converted, &frame) {
                return Err(format!(
                    "message {} decodes {frame:02X?} differently after {format}",
                    original.name
                )
                .into());
            }
        }
    }
    Ok(())
}

fn decoded_by_name(
    codec: &MessageCodec,
    message: &bywire_dbc::Message,
    frame: &[u8],
) -> Option<BTreeMap<String, (u64, u64)>> {
    let mut out = vec![None; message.signals.len()];
    codec.decode(frame, &mut out).ok()?;
    Some(
        message
            .signals
            .iter()
            .zip(out)
            .filter_map(|(s, d)| {
                let d = d?;
                Some((s.name.clone(), (d.raw, d.physical.as_f64().to_bits())))
            })
            .collect(),
    )
}

fn same(expected: &Json, ours: Value) -> bool {
    match (expected, ours) {
        (Json::Number(n), Value::Int(_) | Value::UInt(_)) if n.is_i64() || n.is_u64() => {
            n.as_i64().map(i128::from).or(n.as_u64().map(i128::from)) == ours.as_i128()
        }

        (Json::Number(n), Value::Float(f)) if n.is_f64() => {
            n.as_f64().is_some_and(|x| x.to_bits() == f.to_bits())
        }
        (Json::String(s), Value::Float(f)) => match s.as_str() {
            "NaN" => f.is_nan(),
            "inf" => f == f64::INFINITY,
            "-inf" => f == f64::NEG_INFINITY,
            _ => false,
        },
        _ => false,
    }
}

fn show(v: Option<Value>) -> String {
    format!("{v:?}")
}

fn check_vectors(path: &Path, vectors: &[Json]) -> Result<(), Failed> {
    let bytes = std::fs::read(path).unwrap();
    let (db, diagnostics) = parse(&bytes, Mode::Lenient).unwrap();
    let codecs: BTreeMap<&str, (MessageCodec, Vec<&str>)> = db
        .messages
        .iter()
        .map(|m| {
            let names = m.signals.iter().map(|s| s.display_name()).collect();
            (m.display_name(), (MessageCodec::new(m), names))
        })
        .collect();
    // Class 2: messages whose multiplexor is a lone `m` (found from the diagnostic's line).
    let text = String::from_utf8_lossy(&bytes).into_owned();
    let lines: Vec<&str> = text.lines().collect();
    let lone_m: BTreeSet<&str> = diagnostics
        .iter()
        .filter(|d| d.message.contains("without a value"))
        .filter_map(|d| {
            let upto = lines.get(..usize::try_from(d.line).unwrap())?;
            let bo = upto.iter().rev().find(|l| l.starts_with("BO_ "))?;
            let name = bo.split_whitespace().nth(2)?.trim_end_matches(':');
            db.message_by_name(name).map(|m| m.display_name())
        })
        .collect();
    let mut problems = Vec::new();
    for v in vectors {
        let name = v["message"].as_str().unwrap();
        let Some((codec, names)) = codecs.get(name) else {
            problems.push(format!("no message {name}"));
            continue;
        };
        let payload: Vec<u8> = hex(v["payload_hex"].as_str().unwrap());
        let mut out = vec![None; codec.signal_count()];
        let result = codec.decode(&payload, &mut out);
        let expected = if v["decoded"].is_object() {
            &v["decoded"]
        } else if let Some(per_signal) = v.get("decoded_per_signal") {
            // Class 1: compared signal by signal with cantools' per-signal decode.
            per_signal
        } else {
            let error = v["decode_error"].as_str().unwrap_or("");
            let multiplexed_refusal = error == "DecodeError: unpacking failed"
                && db.messages.iter().any(|m| {
                    m.display_name() == name
                        && m.signals
                            .iter()
                            .any(|s| s.multiplexing != bywire_dbc::Multiplexing::None)
                });
            let ok = multiplexed_refusal
                || (error.contains("expected multiplexer id")
                    && matches!(result, Err(DecodeError::UnknownMultiplexerValue { .. })));
            if !ok {
                problems.push(format!(
                    "{name} {}: cantools '{error}', bywire {result:?}",
                    v["payload_hex"]
                ));
            }
            continue;
        };
        if let Err(e) = result {
            problems.push(format!("{name} {}: bywire {e}", v["payload_hex"]));
            continue;
        }
        let expected = expected.as_object().unwrap();
        let mut ours: BTreeSet<&str> = names
            .iter()
            .zip(&out)
            .filter(|(_, d)| d.is_some())
            .map(|(n, _)| *n)
            .collect();
        let theirs: BTreeSet<&str> = expected.keys().map(String::as_str).collect();
        if lone_m.contains(name) {
            let message = db
                .messages
                .iter()
                .find(|m| m.display_name() == name)
                .unwrap();
            let multiplexed = |n: &str| {
                message.signals.iter().any(|s| {
                    s.display_name() == n
                        && matches!(s.multiplexing, bywire_dbc::Multiplexing::Multiplexed(_))
                })
            };
            ours.retain(|n| theirs.contains(n) || !multiplexed(n));
        }
        if ours != theirs {
            problems.push(format!(
                "{name} {}: signals differ: only bywire {:?}, only cantools {:?}",
                v["payload_hex"],
                ours.difference(&theirs).collect::<Vec<_>>(),
                theirs.difference(&ours).collect::<Vec<_>>()
            ));
            continue;
        }
        for (n, d) in names.iter().zip(&out) {
            if let (Some(e), Some(d)) = (expected.get(*n), d) {
                if !same(e, d.physical) {
                    problems.push(format!(
                        "{name}.{n} {}: cantools {e}, bywire {}",
                        v["payload_hex"],
                        show(Some(d.physical))
                    ));
                }
            }
        }
        if let Some(reencoded) = v["reencoded_hex"].as_str() {
            // Encode what cantools decoded (all of ours but class 2's extra signals).
            let values: Vec<Option<Value>> = names
                .iter()
                .zip(&out)
                .map(|(n, d)| d.filter(|_| theirs.contains(n)).map(|d| d.physical))
                .collect();
            let mut buf = vec![0u8; codec.size()];
            codec.encode(&values, &mut buf).map_err(|e| e.to_string())?;
            let ours: String = buf.iter().map(|b| format!("{b:02x}")).collect();
            if ours != reencoded {
                problems.push(format!(
                    "{name} {}: re-encoded cantools {reencoded}, bywire {ours}",
                    v["payload_hex"]
                ));
            }
        }
    }
    if problems.is_empty() {
        Ok(())
    } else {
        let n = problems.len();
        problems.truncate(8);
        Err(format!(
            "{n} of {} vectors disagree:\n{}",
            vectors.len(),
            problems.join("\n")
        )
        .into())
    }
}

/// Frames a column at a time against frame by frame, over payloads from a fixed generator:
/// the same values in the same order (floats to the bit), and the same messages refused.
fn check_columns(path: &Path) -> Result<(), Failed> {
    let (db, _) = parse(&std::fs::read(path).unwrap(), Mode::Lenient).unwrap();
    let same = |a: Value, b: Value| match (a, b) {
        (Value::Float(x), Value::Float(y)) => x.to_bits() == y.to_bits(),
        _ => a == b,
    };
    let mut state = 0x2545_F491_4F6C_DD1Du64;
    for message in &db.messages {
        let codec = MessageCodec::new(message);
        let mut payloads = Vec::new();
        let mut rows = Vec::new();
        for _ in 0..64 {
            let payload: Vec<u8> = (0..codec.size())
                .map(|_| {
                    state ^= state << 13;
                    state ^= state >> 7;
                    state ^= state << 17;
                    state.to_le_bytes()[0]
                })
                .collect();
            let mut out = vec![None; codec.signal_count()];
            if codec.decode(&payload, &mut out).is_ok() {
                rows.push(out);
                payloads.push(codec.word_of(&payload).unwrap());
            }
        }
        if !codec.decodes_by_word() {
            if codec.decode_column(0, &payloads, &mut Vec::new(), |d| d) {
                return Err(format!("{}: decoded by column, not by word", message.name).into());
            }
            continue;
        }
        if rows.len() != 64 {
            return Err(format!("{}: a payload by word did not decode", message.name).into());
        }
        let short = vec![0u8; codec.size().saturating_sub(1)];
        if codec.size() > 0 && codec.word_of(&short).is_ok() {
            return Err(format!("{}: a short payload was taken", message.name).into());
        }
        for signal in 0..codec.signal_count() {
            let mut column = Vec::new();
            let decoded = codec.decode_column(signal, &payloads, &mut column, |d| d);
            let expected: Vec<Option<Decoded>> = rows.iter().map(|r| r[signal]).collect();
            let agrees = if decoded {
                column.len() == expected.len()
                    && column.iter().zip(&expected).all(|(c, e)| {
                        e.is_some_and(|e| e.raw == c.raw && same(c.physical, e.physical))
                    })
            } else {
                column.is_empty() && expected.iter().all(Option::is_none)
            };
            if !agrees {
                return Err(format!(
                    "{}.{}: by column {column:?}, by frame {expected:?}",
                    message.name, message.signals[signal].name
                )
                .into());
            }
        }
    }
    Ok(())
}

fn hex(s: &str) -> Vec<u8> {
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap())
        .collect()
}

fn main() {
    let args = Arguments::from_args();
    let root = corpus();
    let summary: Json =
        serde_json::from_str(&std::fs::read_to_string(root.join("cantools-summary.json")).unwrap())
            .unwrap();
    let mut vectors: BTreeMap<String, Vec<Json>> = BTreeMap::new();
    let gz =
        flate2::read::GzDecoder::new(std::fs::File::open(root.join("vectors.jsonl.gz")).unwrap());
    for line in std::io::BufReader::new(gz).lines() {
        let v: Json = serde_json::from_str(&line.unwrap()).unwrap();
        vectors
            .entry(v["file"].as_str().unwrap().to_string())
            .or_default()
            .push(v);
    }
    let vectors = Arc::new(vectors);
    let mut trials = Vec::new();
    for group in ["opendbc", "opendbc_generated", "cantools"] {
        let mut files: Vec<PathBuf> = std::fs::read_dir(root.join("dbc").join(group))
            .unwrap()
            .map(|e| e.unwrap().path())
            .collect();
        files.sort();
        for path in files {
            let rel = format!("{group}/{}", path.file_name().unwrap().to_string_lossy());
            let p = path.clone();
            trials.push(Trial::test(format!("load/{rel}"), move || check_load(&p)));
            let p = path.clone();
            trials.push(Trial::test(format!("roundtrip/{rel}"), move || {
                check_roundtrip(&p)
            }));
            let p = path.clone();
            trials.push(Trial::test(format!("json/{rel}"), move || check_json(&p)));
            for format in [bywire_dbc::Format::Kcd, bywire_dbc::Format::Sym] {
                let p = path.clone();
                trials.push(Trial::test(format!("{}/{rel}", format.name()), move || {
                    check_format(&p, format)
                }));
            }
            let p = path.clone();
            trials.push(Trial::test(format!("columns/{rel}"), move || {
                check_columns(&p)
            }));
            let p = path.clone();
            trials.push(Trial::test(format!("schedule/{rel}"), move || {
                check_schedule(&p)
            }));
            if summary["files"][&rel]["nonstrict_ok"] == Json::Bool(false) {
                let p = path.clone();
                trials.push(Trial::test(format!("strict/{rel}"), move || {
                    match parse(&std::fs::read(&p).unwrap(), Mode::Strict) {
                        Err(e)
                            if e.0.line > 0
                                || e.0.message.contains("overlap")
                                || e.0.message.contains("past") =>
                        {
                            Ok(())
                        }
                        Err(e) => Err(format!("rejected without a line: {e}").into()),
                        Ok(_) => Err("strict mode accepted it".into()),
                    }
                }));
            }
            if vectors.contains_key(&rel) {
                let (p, all, key) = (path.clone(), Arc::clone(&vectors), rel.clone());
                trials.push(Trial::test(format!("vectors/{rel}"), move || {
                    check_vectors(&p, &all[&key])
                }));
            }
        }
    }
    libtest_mimic::run(&args, trials).exit();
}
