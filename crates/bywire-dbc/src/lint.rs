//! Checks a database for what will hurt on a real bus: each finding has a severity, a code, a
//! position and a sentence.

use crate::model::*;
use crate::parser::{may_coexist, signal_bits, Severity};

/// One finding.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Finding {
    /// How bad.
    pub severity: Severity,
    /// A stable name for the check (`overlap`, `past-end`, ...).
    pub code: &'static str,
    /// Where.
    pub position: Position,
    /// What, in a sentence.
    pub text: String,
}

/// Names that mark a rolling counter, in opendbc's and common vendors' conventions.
const COUNTER_NAMES: &[&str] = &["COUNTER", "CNT", "ALIVE", "ROLLING", "SEQ"];
/// Names that mark a checksum.
const CHECKSUM_NAMES: &[&str] = &["CHECKSUM", "CHKSUM", "CRC", "CHK", "PARITY"];
/// Names that mark a command (a message that makes an actuator act).
const COMMAND_NAMES: &[&str] = &["CMD", "COMMAND", "CONTROL", "CTRL", "REQUEST", "REQ"];

fn contains_any(name: &str, words: &[&str]) -> bool {
    let upper = name.to_ascii_uppercase();
    words.iter().any(|w| upper.contains(w))
}

/// The findings so far.
#[derive(Default)]
struct Findings(Vec<Finding>);

impl Findings {
    fn push(&mut self, severity: Severity, code: &'static str, position: Position, text: String) {
        self.0.push(Finding {
            severity,
            code,
            position,
            text,
        });
    }
}

/// Run every check.
pub fn lint(db: &Database) -> Vec<Finding> {
    let mut out = Findings::default();
    let (mut little, mut big) = (None, None);
    // Names seen so far: a duplicate found in constant time (a search made lint quadratic).
    let mut names = std::collections::HashSet::new();
    for m in &db.messages {
        if m.name == crate::INDEPENDENT_SIGNALS {
            continue;
        }
        message_findings(db, m, &mut names, &mut out);
        let mut used: Vec<(&Signal, [u64; 8])> = Vec::new();
        for (j, s) in m.signals.iter().enumerate() {
            if m.signals.iter().take(j).any(|o| o.name == s.name) {
                out.push(
                    Severity::Error,
                    "duplicate-name",
                    s.position,
                    format!("signal name {} is used twice in message {}", s.name, m.name),
                );
            }
            match s.byte_order {
                ByteOrder::LittleEndian => little = little.or(Some(s.position)),
                ByteOrder::BigEndian => big = big.or(Some(s.position)),
            }
            signal_findings(m, s, &mut used, &mut out);
        }
        command_protection(m, &mut out);
    }
    if let (Some(_), Some(at)) = (little, big) {
        out.push(
            Severity::Info,
            "mixed-byte-order",
            at,
            "the database mixes little-endian and big-endian signals".into(),
        );
    }
    for (i, n) in db.nodes.iter().enumerate() {
        if db.nodes.iter().take(i).any(|o| o.name == n.name) {
            out.push(
                Severity::Error,
                "duplicate-name",
                Position::default(),
                format!("node name {} is used twice", n.name),
            );
        }
    }
    out.0
}

/// A message's identifier, name (against `names`, those seen so far) and cycle time.
fn message_findings<'a>(
    db: &Database,
    m: &'a Message,
    names: &mut std::collections::HashSet<&'a str>,
    out: &mut Findings,
) {
    let limit = if m.extended { 0x1FFF_FFFF } else { 0x7FF };
    if m.id > limit {
        out.push(
            Severity::Error,
            "id-format",
            m.position,
            format!(
                "message {} has id {:#X}, outside the {} range",
                m.name,
                m.id,
                if m.extended { "29-bit" } else { "11-bit" }
            ),
        );
    }
    if !names.insert(m.name.as_str()) {
        out.push(
            Severity::Error,
            "duplicate-name",
            m.position,
            format!("message name {} is used twice", m.name),
        );
    }
    let send_type = db
        .message_attribute_text(m, "GenMsgSendType")
        .unwrap_or_default()
        .to_ascii_lowercase();
    let cycle = db
        .message_attribute_text(m, "GenMsgCycleTime")
        .and_then(|c| c.parse::<f64>().ok())
        .unwrap_or(0.0);
    if send_type.contains("cyclic") && !send_type.contains("no") && cycle <= 0.0 {
        out.push(
            Severity::Warning,
            "no-cycle-time",
            m.position,
            format!(
                "message {} is sent cyclically but has no GenMsgCycleTime",
                m.name
            ),
        );
    }
}

/// A signal's place in its message (past the end, overlapping another), alignment, scale and
/// range.
fn signal_findings<'a>(
    m: &Message,
    s: &'a Signal,
    used: &mut Vec<(&'a Signal, [u64; 8])>,
    out: &mut Findings,
) {
    if let Some((bits, last_byte)) = signal_bits(s) {
        if last_byte >= m.size {
            out.push(
                Severity::Error,
                "past-end",
                s.position,
                format!(
                    "signal {} runs past the {} bytes of message {}",
                    s.name, m.size, m.name
                ),
            );
        }
        if let Some((other, _)) = used
            .iter()
            .find(|(o, ob)| may_coexist(o, s) && ob.iter().zip(&bits).any(|(a, b)| a & b != 0))
        {
            out.push(
                Severity::Error,
                "overlap",
                s.position,
                format!(
                    "signals {} and {} of message {} share bits",
                    other.name, s.name, m.name
                ),
            );
        }
        used.push((s, bits));
    }
    let aligned = match s.byte_order {
        ByteOrder::LittleEndian => s.start_bit.is_multiple_of(8),
        ByteOrder::BigEndian => s.start_bit % 8 == 7,
    };
    if s.length.is_multiple_of(8) && !aligned {
        out.push(
            Severity::Info,
            "unaligned",
            s.position,
            format!(
                "signal {} is {} whole bytes long but does not start on a byte boundary",
                s.name,
                s.length / 8
            ),
        );
    }
    let (factor, offset) = (s.factor.as_f64(), s.offset.as_f64());
    if factor == 0.0 {
        out.push(
            Severity::Error,
            "zero-scale",
            s.position,
            format!(
                "signal {} has scale 0: every raw value means the same",
                s.name
            ),
        );
    } else if let Some((phys_lo, phys_hi)) = s.reachable_range() {
        let (min, max) = (s.minimum.as_f64(), s.maximum.as_f64());
        let declared = !(min == 0.0 && max == 0.0);
        // Half a step of slack: limits are often written rounded.
        let slack = factor.abs() / 2.0;
        if declared && (min < phys_lo - slack || max > phys_hi + slack) {
            out.push(Severity::Warning, "range", s.position, format!("signal {} declares [{min}, {max}] but its {} raw bits with scale {factor} and offset {offset} reach only [{phys_lo}, {phys_hi}]", s.name, s.length));
        }
        if declared && min > max {
            out.push(
                Severity::Warning,
                "range",
                s.position,
                format!("signal {} has minimum {min} above maximum {max}", s.name),
            );
        }
    }
}

/// A command message without a rolling counter or a checksum.
fn command_protection(m: &Message, out: &mut Findings) {
    let command = contains_any(&m.name, COMMAND_NAMES)
        || m.comment
            .as_deref()
            .is_some_and(|c| contains_any(c, &["COMMAND"]));
    if command && !m.signals.is_empty() {
        let counter = m
            .signals
            .iter()
            .any(|s| contains_any(&s.name, COUNTER_NAMES));
        let checksum = m
            .signals
            .iter()
            .any(|s| contains_any(&s.name, CHECKSUM_NAMES));
        if !counter || !checksum {
            let missing = match (counter, checksum) {
                (false, false) => "rolling counter and no checksum",
                (false, true) => "rolling counter",
                _ => "checksum",
            };
            out.push(Severity::Warning, "unprotected-command", m.position, format!("command message {} has no {missing}: a stale or corrupted command cannot be detected", m.name));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{parse_str, Mode};

    fn codes(text: &str) -> Vec<&'static str> {
        let (db, _) = parse_str(text, Mode::Lenient).unwrap();
        lint(&db).into_iter().map(|f| f.code).collect()
    }

    #[test]
    fn each_check_fires_on_its_problem_and_only_there() {
        let clean = "BO_ 256 AdsCmd: 8 ADS\n SG_ Speed : 0|16@1+ (0.01,0) [0|655.35] \"m/s\" ECU\n SG_ Counter : 16|4@1+ (1,0) [0|15] \"\" ECU\n SG_ Checksum : 24|8@1+ (1,0) [0|255] \"\" ECU\n";
        assert_eq!(codes(clean), Vec::<&str>::new());
        assert_eq!(
            codes("BO_ 256 AdsCmd: 8 ADS\n SG_ Speed : 0|16@1+ (0.01,0) [0|655.35] \"\" ECU\n"),
            ["unprotected-command"]
        );
        assert_eq!(codes("BO_ 1 M: 8 N\n SG_ A : 0|16@1+ (1,0) [0|0] \"\" N\n SG_ B : 8|8@1+ (1,0) [0|0] \"\" N\n"), ["overlap"]);
        assert_eq!(
            codes("BO_ 1 M: 2 N\n SG_ A : 4|16@1+ (1,0) [0|0] \"\" N\n"),
            ["past-end", "unaligned"]
        );
        assert_eq!(
            codes("BO_ 1 M: 8 N\n SG_ A : 0|8@1+ (1,0) [0|300] \"\" N\n"),
            ["range"]
        );
        assert_eq!(
            codes("BO_ 1 M: 8 N\n SG_ A : 0|8@1+ (0,0) [0|0] \"\" N\n"),
            ["zero-scale"]
        );
        assert_eq!(codes("BO_ 1 M: 8 N\n SG_ A : 0|8@1+ (1,0) [0|0] \"\" N\n SG_ A : 8|8@1+ (1,0) [0|0] \"\" N\n"), ["duplicate-name"]);
        assert_eq!(codes("BO_ 1 M: 8 N\n SG_ A : 0|8@1+ (1,0) [0|0] \"\" N\n SG_ B : 15|8@0+ (1,0) [0|0] \"\" N\n"), ["mixed-byte-order"]);
        // 0x12345678 without the extended flag is read as extended (with a diagnostic);
        // an extended id with flag 31 set and bits above 29 is outside its format.
        assert_eq!(codes("BO_ 4294967295 M: 8 N\n"), ["id-format"]);
        let cyclic = "BA_DEF_ BO_ \"GenMsgSendType\" ENUM \"Cyclic\",\"NoMsgSendType\";\nBA_DEF_ BO_ \"GenMsgCycleTime\" INT 0 10000;\nBA_DEF_DEF_ \"GenMsgSendType\" 0;\nBA_DEF_DEF_ \"GenMsgCycleTime\" 0;\nBO_ 1 M: 8 N\n SG_ A : 0|8@1+ (1,0) [0|0] \"\" N\n";
        assert_eq!(codes(cyclic), ["no-cycle-time"]);
        assert_eq!(
            codes(&format!("{cyclic}BA_ \"GenMsgCycleTime\" BO_ 1 20;\n")),
            Vec::<&str>::new()
        );
    }

    #[test]
    fn findings_carry_positions() {
        let (db, _) = parse_str("BO_ 1 M: 8 N\n SG_ A : 0|16@1+ (1,0) [0|0] \"\" N\n SG_ B : 8|8@1+ (1,0) [0|0] \"\" N\n", Mode::Lenient).unwrap();
        let f = lint(&db);
        assert_eq!((f[0].position.line, f[0].position.column), (3, 2));
    }
}
