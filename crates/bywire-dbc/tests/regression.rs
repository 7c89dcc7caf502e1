//! Inputs that once broke something, named after the problem, kept as files in `regressions/`.
// Tests fail by panicking.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing
)]

use bywire_dbc::{parse, parse_str, write, Mode};

fn round_trips(name: &str) {
    let path = format!("{}/tests/regressions/{name}", env!("CARGO_MANIFEST_DIR"));
    let (db, _) = parse(&std::fs::read(path).unwrap(), Mode::Lenient).unwrap();
    let (again, _) = parse_str(&write(&db), Mode::Lenient).unwrap();
    assert_eq!(again, db);
}

/// Found by fuzzing: an unknown statement whose string runs to the end of the file used to be
/// written before the comments and attribute definitions, and swallowed them on reload.
#[test]
fn unterminated_string_in_unknown_statement() {
    round_trips("unterminated_string_in_unknown_statement.dbc");
}

/// Found by fuzzing: two statements kept verbatim, the first without a `;`, merged into one when
/// read back, because an unknown statement only ended at `;` or a known keyword.
#[test]
fn unknown_statements_merged_on_reload() {
    round_trips("unknown_statements_merged_on_reload.dbc");
}

/// Found by fuzzing: a signal with no receivers was written back with `Vector__XXX`, which read
/// back as a receiver list of one.
#[test]
fn signal_without_receivers() {
    round_trips("signal_without_receivers.dbc");
}

/// Found by fuzzing: `BS_` content with a string running over several lines was kept verbatim
/// and swallowed the statements after it when written back.
#[test]
fn string_in_bit_timing_section() {
    round_trips("string_in_bit_timing_section.dbc");
}

/// A signal name used twice in one message, and a file without messages, loaded without a
/// word: each is now a warning with its position.
#[test]
fn duplicate_signal_names_and_empty_files_are_warned_about() {
    let text =
        "BO_ 1 M: 8 X\n SG_ S : 0|8@1+ (1,0) [0|0] \"\" X\n SG_ S : 8|8@1+ (1,0) [0|0] \"\" X\n";
    let (_, diagnostics) = parse_str(text, Mode::Lenient).unwrap();
    let twice: Vec<_> = diagnostics
        .iter()
        .filter(|d| d.message.contains("signal S is defined twice in message M"))
        .collect();
    assert_eq!(twice.len(), 1, "{diagnostics:?}");
    assert_eq!(
        (twice[0].line, twice[0].severity),
        (3, bywire_dbc::Severity::Warning)
    );
    let (_, diagnostics) = parse_str("VERSION \"\"\n\nBU_: A B\n", Mode::Lenient).unwrap();
    assert!(
        diagnostics
            .iter()
            .any(|d| d.message == "the file defines no messages" && d.line == 1),
        "{diagnostics:?}"
    );
    let (_, diagnostics) = parse_str(
        "BO_ 1 M: 8 X\n SG_ S : 0|8@1+ (1,0) [0|0] \"\" X\n",
        Mode::Lenient,
    )
    .unwrap();
    assert!(diagnostics.is_empty(), "{diagnostics:?}");
}

/// Found on a real file (opendbc's Tesla powertrain): `BU_:` with one node a line, indented,
/// read as unknown statements, so the nodes were missing and the written file was one
/// cantools rejects. A word at the start of a line still begins a statement.
#[test]
fn nodes_listed_one_a_line() {
    let text = "VERSION \"\"\n\nBU_:\n\tNEO\n\tMCU GTW\nVENDOR_THING 1;\nBO_ 1 M: 8 NEO\n";
    let (db, diagnostics) = parse_str(text, Mode::Lenient).unwrap();
    let nodes: Vec<&str> = db.nodes.iter().map(|n| n.name.as_str()).collect();
    assert_eq!(nodes, ["NEO", "MCU", "GTW"]);
    assert!(
        diagnostics
            .iter()
            .any(|d| d.message.contains("unknown statement 'VENDOR_THING'")),
        "{diagnostics:?}"
    );
    let (again, _) = parse_str(&write(&db), Mode::Lenient).unwrap();
    assert_eq!(again, db);
}

/// A number without a digit before its point is read and the warning says as what (it used to
/// print the placeholder "read as 0{n}").
#[test]
fn a_number_without_a_leading_digit_says_what_it_was_read_as() {
    let text = "BU_: A\nBO_ 1 M: 8 A\n SG_ S : 0|8@1+ (.25,-.5) [0|1] \"\" A\n";
    let (db, diagnostics) = parse_str(text, Mode::Lenient).unwrap();
    let signal = &db.messages[0].signals[0];
    assert_eq!(
        (signal.factor.as_f64(), signal.offset.as_f64()),
        (0.25, -0.5)
    );
    let resolutions: Vec<&str> = diagnostics.iter().map(|d| d.resolution.as_str()).collect();
    assert_eq!(resolutions, ["read as 0.25", "read as -0.5"]);
}
