//! SYM, the PCAN Symbol Editor's format (version 6.0), as cantools reads it.
//!
//! A file declares `{ENUMS}` (value tables), `{SIGNALS}` (signals by name, placed in messages
//! with `Sig=name start`) and messages under `{SEND}`, `{RECEIVE}` and `{SENDRECEIVE}`, each a
//! `[symbol]` with `ID=`, `Len=`, `Type=`, `CycleTime=`, its own variables (`Var=`) and, when
//! multiplexed, one section per multiplexor value (`Mux=`), the later ones without `ID=`.
//! An `ID=lo-hi` range is one message per identifier. What cantools does, this reader does: a
//! message sent by the ECU is sent by node `ECU`, one it receives by `Peripherals`; a
//! big-endian start bit is DBC's with the bits of its byte reversed. Where cantools makes one
//! signal per multiplexor value, this reader makes one signal present for several values (an
//! extended multiplexing condition), and one present for every value an ordinary signal.

use std::collections::HashMap;

use crate::format::{
    self, attrs, cycle_time_ms, drop_dbc_only, keep_attributes, plain_signal,
    start_bit_from_network, Omission, Omissions, Report, NO_NODE,
};
use crate::model::*;
use crate::parser::{parse_num, Diagnostic, Mode, ParseError, Severity};

/// The node that sends a `{SEND}` message (cantools' name for it).
const SENDER: &str = "ECU";
/// The node that sends a `{RECEIVE}` message.
const RECEIVER: &str = "Peripherals";
/// Messages one `ID=lo-hi` range may make.
const MAX_RANGE: u32 = 4096;
/// Values of a multiplexor a signal may be written under.
const MAX_GROUPS_PER_SIGNAL: u64 = 256;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Section {
    Enums,
    Signals,
    Send,
    Receive,
    SendReceive,
}

/// One statement: its key, the text after `=`, the comment after `//`, and where it began.
struct Statement<'t> {
    key: &'t str,
    value: String,
    comment: Option<String>,
    at: Position,
}

/// A signal as `Sig=` or `Var=` declares it, not yet placed.
#[derive(Clone)]
struct Declared {
    signal: Signal,
    /// `/d:`, the physical value before anything was received.
    default: Option<Num>,
}

#[derive(Default)]
struct Symbol {
    name: String,
    at: Position,
    section: Option<Section>,
    id: Option<(u32, u32, bool)>,
    kind: Option<String>,
    length: Option<u32>,
    cycle_ms: Option<u64>,
    comment: Option<String>,
    mux: Option<(Signal, u64)>,
    signals: Vec<Signal>,
}

/// Read SYM text.
pub(crate) fn read(text: &str, mode: Mode) -> Result<(Database, Vec<Diagnostic>), ParseError> {
    let mut reader = Reader {
        report: Report::new(mode),
        enums: HashMap::new(),
        declared: HashMap::new(),
        symbols: Vec::new(),
        orphan: Symbol::default(),
        db: Database::default(),
    };
    reader.statements(text)?;
    let db = reader.build()?;
    reader.report.finish(db)
}

struct Reader {
    report: Report,
    enums: HashMap<String, Vec<(i128, String)>>,
    declared: HashMap<String, Declared>,
    symbols: Vec<Symbol>,
    orphan: Symbol,
    db: Database,
}

/// `text` split at white space, a `"…"` (with `\"` inside) one word without its quotes.
fn words(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut chars = text.chars().peekable();
    while let Some(&c) = chars.peek() {
        if c.is_whitespace() {
            chars.next();
            continue;
        }
        let mut word = String::new();
        let mut quoted = false;
        while let Some(&c) = chars.peek() {
            if c.is_whitespace() && !quoted {
                break;
            }
            chars.next();
            match c {
                '\\' if quoted && chars.peek() == Some(&'"') => {
                    word.push('"');
                    chars.next();
                }
                '"' => quoted = !quoted,
                c => word.push(c),
            }
        }
        out.push(word);
    }
    out
}

/// The byte where a `//` comment starts, outside quotes.
fn comment_start(line: &str) -> Option<usize> {
    let bytes = line.as_bytes();
    let mut quoted = false;
    let mut i = 0;
    while i < bytes.len() {
        match bytes.get(i) {
            Some(b'\\') if quoted => i += 1,
            Some(b'"') => quoted = !quoted,
            Some(b'/') if !quoted && bytes.get(i + 1) == Some(&b'/') => return Some(i),
            _ => {}
        }
        i += 1;
    }
    None
}

fn position(line: usize, column: usize) -> Position {
    Position {
        line: u32::try_from(line + 1).unwrap_or(u32::MAX),
        column: u32::try_from(column + 1).unwrap_or(u32::MAX),
    }
}

/// A hexadecimal number ending in `h` (`7FFh`).
fn hex(text: &str) -> Option<u64> {
    u64::from_str_radix(text.strip_suffix(['h', 'H'])?, 16).ok()
}

impl Reader {
    fn problem(
        &mut self,
        at: Position,
        message: impl Into<String>,
        resolution: &str,
    ) -> Result<(), ParseError> {
        self.report.add(Severity::Error, at, message, resolution)
    }

    /// Split the text into statements and file each under its section and symbol.
    fn statements(&mut self, text: &str) -> Result<(), ParseError> {
        let mut section: Option<Section> = None;
        let mut version_seen = false;
        let mut lines = text.lines().enumerate();
        while let Some((number, raw)) = lines.next() {
            let (mut body, mut comment) = match comment_start(raw) {
                Some(i) => (
                    raw.get(..i).unwrap_or_default().to_string(),
                    raw.get(i + 2..).map(|c| c.trim().to_string()),
                ),
                None => (raw.to_string(), None),
            };
            let indent = body.len() - body.trim_start().len();
            let trimmed = body.trim().to_string();
            if trimmed.is_empty() {
                continue;
            }
            let at = position(number, indent);
            // An enumeration runs until its parenthesis closes, however many lines it takes.
            if trimmed.starts_with("Enum") {
                let mut joined = trimmed.clone();
                while joined.matches('(').count() > joined.matches(')').count() {
                    let Some((_, next)) = lines.next() else { break };
                    let next_body = match comment_start(next) {
                        Some(i) => next.get(..i).unwrap_or_default(),
                        None => next,
                    };
                    joined.push(' ');
                    joined.push_str(next_body.trim());
                }
                body = joined;
                comment = None;
            }
            let body = body.trim();
            if let Some(name) = body.strip_prefix('{').and_then(|b| b.strip_suffix('}')) {
                section = match name {
                    "ENUMS" => Some(Section::Enums),
                    "SIGNALS" => Some(Section::Signals),
                    "SEND" => Some(Section::Send),
                    "RECEIVE" => Some(Section::Receive),
                    "SENDRECEIVE" => Some(Section::SendReceive),
                    other => {
                        self.problem(
                            at,
                            format!("unknown section {{{other}}}"),
                            "its statements skipped",
                        )?;
                        None
                    }
                };
                continue;
            }
            if let Some(name) = body.strip_prefix('[').and_then(|b| b.strip_suffix(']')) {
                if !matches!(
                    section,
                    Some(Section::Send | Section::Receive | Section::SendReceive)
                ) {
                    self.problem(
                        at,
                        format!(
                            "symbol [{name}] outside {{SEND}}, {{RECEIVE}} and {{SENDRECEIVE}}"
                        ),
                        "symbol skipped",
                    )?;
                }
                self.symbols.push(Symbol {
                    name: name.trim_matches('"').to_string(),
                    at,
                    section,
                    ..Symbol::default()
                });
                continue;
            }
            let Some((key, value)) = body.split_once('=') else {
                self.problem(
                    at,
                    format!("'{body}' is not a statement (key=value)"),
                    "line skipped",
                )?;
                continue;
            };
            let statement = Statement {
                key: key.trim(),
                value: value.trim().to_string(),
                comment: comment.filter(|c| !c.is_empty()),
                at,
            };
            if !version_seen {
                if statement.key != "FormatVersion" {
                    return Err(Report::fatal(at, "a SYM file begins with FormatVersion="));
                }
                version_seen = true;
                let version = words(&statement.value)
                    .into_iter()
                    .next()
                    .unwrap_or_default();
                if version != "6.0" {
                    self.report.add(
                        Severity::Warning,
                        at,
                        format!("SYM version {version}; this reader knows 6.0"),
                        "read as 6.0",
                    )?;
                }
                self.db.version = version;
                continue;
            }
            self.statement(section, statement)?;
        }
        if !version_seen {
            return Err(Report::fatal(
                position(0, 0),
                "a SYM file begins with FormatVersion=",
            ));
        }
        Ok(())
    }

    fn statement(&mut self, section: Option<Section>, s: Statement<'_>) -> Result<(), ParseError> {
        match (section, s.key) {
            (None, "Title") => {
                self.db.comment = Some(words(&s.value).join(" ")).filter(|t| !t.is_empty())
            }
            (None, _) => {}
            (Some(Section::Enums), "Enum") => self.enumeration(&s)?,
            (Some(Section::Signals), "Sig") => {
                if let Some(d) = self.declaration(&s, false)? {
                    self.declared.insert(d.signal.name.clone(), d);
                }
            }
            (Some(Section::Send | Section::Receive | Section::SendReceive), _) => {
                self.symbol_statement(s)?
            }
            (Some(_), key) => self.problem(
                s.at,
                format!("{key}= does not belong in this section"),
                "statement skipped",
            )?,
        }
        Ok(())
    }

    fn enumeration(&mut self, s: &Statement<'_>) -> Result<(), ParseError> {
        let Some((name, rest)) = s.value.split_once('(') else {
            return self.problem(s.at, "an Enum without (values)", "enum skipped");
        };
        let body = rest.trim_end().strip_suffix(')').unwrap_or(rest);
        let mut values = Vec::new();
        for item in split_outside_quotes(body, ',') {
            let item = item.trim();
            if item.is_empty() {
                continue;
            }
            let parsed = item
                .split_once('=')
                .and_then(|(v, d)| Some((v.trim().parse::<i128>().ok()?, words(d).join(" "))));
            match parsed {
                Some(pair) => values.push(pair),
                None => self.problem(
                    s.at,
                    format!(
                        "enum {}'s entry '{item}' is not number=\"name\"",
                        name.trim()
                    ),
                    "entry skipped",
                )?,
            }
        }
        self.enums
            .insert(name.trim().trim_matches('"').to_string(), values);
        Ok(())
    }

    /// A `Sig=` (name, type, length, flags, attributes) or `Var=` (name, type, start,length,
    /// flags, attributes); a `Var`'s start comes back in the signal's start bit as written.
    fn declaration(
        &mut self,
        s: &Statement<'_>,
        variable: bool,
    ) -> Result<Option<Declared>, ParseError> {
        let words = words(&s.value);
        let mut it = words.iter().peekable();
        let (Some(name), Some(kind)) = (it.next(), it.next()) else {
            self.problem(
                s.at,
                format!("{}= needs a name and a type", s.key),
                "signal skipped",
            )?;
            return Ok(None);
        };
        let mut start = 0;
        let mut length: Option<u32> = None;
        if variable {
            let place = it.next().map(String::as_str).unwrap_or_default();
            match place
                .split_once(',')
                .map(|(a, b)| (a.trim().parse(), b.trim().parse()))
            {
                Some((Ok(a), Ok(b))) => {
                    start = a;
                    length = Some(b);
                }
                _ => {
                    self.problem(
                        s.at,
                        format!("variable {name}'s place '{place}' is not start,length"),
                        "signal skipped",
                    )?;
                    return Ok(None);
                }
            }
        } else if let Some(n) = it.peek().and_then(|w| w.parse::<u32>().ok()) {
            it.next();
            length = Some(n);
        }
        let mut value_type = ValueType::Integer { signed: false };
        let mut enumeration = None;
        let (mut minimum, mut maximum) = (None, None);
        let length = match kind.as_str() {
            "signed" => {
                value_type = ValueType::Integer { signed: true };
                length
            }
            "unsigned" | "string" | "raw" => length,
            "float" => {
                value_type = ValueType::Float32;
                Some(32)
            }
            "double" => {
                value_type = ValueType::Float64;
                Some(64)
            }
            "bit" => {
                (minimum, maximum) = (Some(Num::Int(0)), Some(Num::Int(1)));
                Some(1)
            }
            "char" => Some(8),
            other => {
                match self.enums.get(other) {
                    Some(values) => {
                        enumeration = Some(values.clone());
                        length
                    }
                    None => {
                        self.problem(s.at, format!("signal {name}'s type {other} is no type or enum declared before it"), "signal skipped")?;
                        return Ok(None);
                    }
                }
            }
        };
        let Some(length) = length.filter(|l| (1..=64).contains(l)) else {
            self.problem(
                s.at,
                format!("signal {name} needs a length of 1 to 64 bits"),
                "signal skipped",
            )?;
            return Ok(None);
        };
        let mut signal = plain_signal(
            name.clone(),
            (start, length, ByteOrder::LittleEndian),
            Multiplexing::None,
            s.at,
        );
        signal.value_type = value_type;
        signal.comment.clone_from(&s.comment);
        signal.value_descriptions = enumeration.unwrap_or_default();
        let mut default = None;
        for word in it {
            if word == "-m" {
                signal.byte_order = ByteOrder::BigEndian;
                continue;
            }
            if word.starts_with('-') {
                continue; // display flags: -h hexadecimal, -b binary, -v, -s
            }
            let Some((key, value)) = word.strip_prefix('/').and_then(|w| w.split_once(':')) else {
                self.problem(
                    s.at,
                    format!("signal {name}'s '{word}' is not a /key:value"),
                    "ignored",
                )?;
                continue;
            };
            let number = parse_num(value);
            match (key, number) {
                ("u", _) => signal.unit = value.to_string(),
                ("f", Some(n)) => signal.factor = n,
                ("o", Some(n)) => signal.offset = n,
                ("min", Some(n)) => minimum = Some(n),
                ("max", Some(n)) => maximum = Some(n),
                ("d", Some(n)) => default = Some(n),
                ("d", None) | ("p", _) => {}
                ("spn", Some(Num::Int(n))) => signal
                    .attributes
                    .push((attrs::SPN.into(), AttrValue::Number(Num::Int(n)))),
                ("ln", _) => signal
                    .attributes
                    .push((attrs::LONG_NAME.into(), AttrValue::Str(value.to_string()))),
                ("e", _) => match self.enums.get(value) {
                    Some(values) => signal.value_descriptions = values.clone(),
                    None => self.problem(
                        s.at,
                        format!("signal {name}'s enum {value} is not declared"),
                        "no value names",
                    )?,
                },
                (_, _) => self.problem(
                    s.at,
                    format!("signal {name}'s /{key}:{value} is not understood"),
                    "ignored",
                )?,
            }
        }
        format::set_range(&mut signal, minimum, maximum);
        Ok(Some(Declared { signal, default }))
    }

    fn symbol_statement(&mut self, s: Statement<'_>) -> Result<(), ParseError> {
        if self.symbols.is_empty() {
            return self.problem(
                s.at,
                format!("{}= before any [symbol]", s.key),
                "statement skipped",
            );
        }
        match s.key {
            "ID" => self.identifier(&s)?,
            "Len" | "DLC" => match s.value.parse::<u32>() {
                Ok(n) if n <= 64 => self.current().length = Some(n),
                _ => self.problem(
                    s.at,
                    format!("length {} is not 0 to 64 bytes", s.value),
                    "8 bytes",
                )?,
            },
            "Type" => self.current().kind = Some(s.value.clone()),
            "CycleTime" => match words(&s.value).first().map(|w| w.parse::<u64>()) {
                Some(Ok(ms)) => self.current().cycle_ms = Some(ms).filter(|&ms| ms > 0),
                _ => self.problem(
                    s.at,
                    format!("cycle time {} is not whole milliseconds", s.value),
                    "no cycle time",
                )?,
            },
            "Mux" => self.multiplexor(&s)?,
            "Var" => {
                if let Some(d) = self.declaration(&s, true)? {
                    let signal = self.placed(d);
                    self.current().signals.push(signal);
                }
            }
            "Sig" => {
                let words = words(&s.value);
                let (Some(name), Some(start)) = (
                    words.first(),
                    words.get(1).and_then(|w| w.parse::<u32>().ok()),
                ) else {
                    return self.problem(
                        s.at,
                        "Sig= in a symbol needs a name and a start bit",
                        "signal skipped",
                    );
                };
                match self.declared.get(name).cloned() {
                    Some(mut d) => {
                        d.signal.start_bit = start;
                        d.signal.position = s.at;
                        let signal = self.placed(d);
                        self.current().signals.push(signal);
                    }
                    None => self.problem(
                        s.at,
                        format!("signal {name} is not declared under {{SIGNALS}}"),
                        "signal skipped",
                    )?,
                }
            }
            "Timeout" | "MinInterval" | "Color" => {}
            key => self.problem(
                s.at,
                format!("{key}= is not a symbol's statement"),
                "ignored",
            )?,
        }
        Ok(())
    }

    /// The symbol being read (statements before any symbol were refused before this).
    fn current(&mut self) -> &mut Symbol {
        match self.symbols.last_mut() {
            Some(symbol) => symbol,
            None => &mut self.orphan,
        }
    }

    /// A declared signal placed at its start bit, its default turned into a raw start value.
    fn placed(&self, d: Declared) -> Signal {
        let mut signal = d.signal;
        signal.start_bit = start_bit_from_network(signal.byte_order, signal.start_bit);
        if let Some(default) = d.default.and_then(|p| raw_of_physical(&signal, p)) {
            signal
                .attributes
                .push((attrs::START_VALUE.into(), AttrValue::Number(default)));
        }
        signal
    }

    fn identifier(&mut self, s: &Statement<'_>) -> Result<(), ParseError> {
        let text = words(&s.value).into_iter().next().unwrap_or_default();
        let (low, high) = match text.split_once('-') {
            Some((a, b)) => (a.to_string(), Some(b.to_string())),
            None => (text.clone(), None),
        };
        let Some(lo) = hex(&low).and_then(|v| u32::try_from(v).ok()) else {
            return self.problem(
                s.at,
                format!("identifier {text} is not hexadecimal ending in h"),
                "symbol skipped",
            );
        };
        let hi = match high.as_deref().map(hex) {
            None => lo,
            Some(Some(h)) => u32::try_from(h).unwrap_or(u32::MAX),
            Some(None) => {
                return self.problem(
                    s.at,
                    format!("identifier range {text} does not end in hexadecimal"),
                    "symbol skipped",
                )
            }
        };
        if hi < lo || hi - lo >= MAX_RANGE {
            return self.problem(
                s.at,
                format!("identifier range {text} is empty or over {MAX_RANGE} identifiers"),
                "symbol skipped",
            );
        }
        let eight_digits = low.len() == 9;
        let comment = s.comment.clone();
        let symbol = self.current();
        symbol.id = Some((lo, hi, eight_digits));
        symbol.comment = comment;
        Ok(())
    }

    fn multiplexor(&mut self, s: &Statement<'_>) -> Result<(), ParseError> {
        let words = words(&s.value);
        let name = words.first().cloned().unwrap_or_default();
        let place = words
            .get(1)
            .and_then(|p| p.split_once(','))
            .map(|(a, b)| (a.trim().parse::<u32>(), b.trim().parse::<u32>()));
        let value = words.get(2).and_then(|v| hex(v).or_else(|| v.parse().ok()));
        let (Some((Ok(start), Ok(length))), Some(value)) = (place, value) else {
            return self.problem(
                s.at,
                format!("Mux={} is not name start,length value", s.value),
                "symbol's multiplexing skipped",
            );
        };
        if !(1..=64).contains(&length) {
            return self.problem(
                s.at,
                format!("multiplexor {name} needs 1 to 64 bits"),
                "symbol's multiplexing skipped",
            );
        }
        let byte_order = if words.iter().any(|w| w == "-m") {
            ByteOrder::BigEndian
        } else {
            ByteOrder::LittleEndian
        };
        let mut signal = plain_signal(
            name,
            (
                start_bit_from_network(byte_order, start),
                length,
                byte_order,
            ),
            Multiplexing::Multiplexor,
            s.at,
        );
        signal.comment.clone_from(&s.comment);
        self.current().mux = Some((signal, value));
        Ok(())
    }

    /// Messages from the symbols: `{SEND}`, then `{RECEIVE}`, then `{SENDRECEIVE}` (cantools'
    /// order), each identifier of a range a message, multiplexed sections joined by name.
    fn build(&mut self) -> Result<Database, ParseError> {
        let mut db = std::mem::take(&mut self.db);
        let symbols = std::mem::take(&mut self.symbols);
        for section in [Section::Send, Section::Receive, Section::SendReceive] {
            let in_section: Vec<&Symbol> = symbols
                .iter()
                .filter(|s| s.section == Some(section))
                .collect();
            for symbol in &in_section {
                let Some((lo, hi, eight_digits)) = symbol.id else {
                    continue;
                };
                let kind = symbol
                    .kind
                    .as_deref()
                    .unwrap_or("Standard")
                    .to_ascii_lowercase();
                let extended = eight_digits || kind.contains("extended");
                let fd = kind.starts_with("fd");
                let signals = self.message_signals(symbol, &in_section)?;
                let (transmitter, senders) = match section {
                    Section::Send => (SENDER, vec![]),
                    Section::Receive => (RECEIVER, vec![]),
                    _ => (SENDER, vec![RECEIVER.to_string()]),
                };
                let mut attributes = Vec::new();
                if let Some(ms) = symbol.cycle_ms {
                    attributes.push((
                        attrs::CYCLE_TIME.to_string(),
                        AttrValue::Number(Num::Int(i128::from(ms))),
                    ));
                }
                if fd {
                    attributes.push((
                        attrs::FRAME_FORMAT.to_string(),
                        AttrValue::Number(Num::Int(if extended { 3 } else { 2 })),
                    ));
                }
                if extended && hi > 0x1FFF_FFFF || !extended && hi > 0x7FF {
                    self.problem(
                        symbol.at,
                        format!(
                            "message {}'s identifier {hi:#X} is too large for its format",
                            symbol.name
                        ),
                        "message skipped",
                    )?;
                    continue;
                }
                for id in lo..=hi {
                    db.messages.push(Message {
                        id,
                        extended,
                        name: symbol.name.clone(),
                        size: symbol.length.unwrap_or(8),
                        transmitter: transmitter.to_string(),
                        senders: senders.clone(),
                        signals: signals.clone(),
                        comment: symbol.comment.clone(),
                        attributes: attributes.clone(),
                        position: symbol.at,
                    });
                }
            }
        }
        attrs::define_used(&mut db);
        Ok(db)
    }

    fn message_signals(
        &mut self,
        symbol: &Symbol,
        section: &[&Symbol],
    ) -> Result<Vec<Signal>, ParseError> {
        let Some((multiplexor, _)) = &symbol.mux else {
            return Ok(symbol.signals.clone());
        };
        // The symbol's own section, then every other of its name in the same section.
        let mut groups: Vec<(u64, &[Signal])> = Vec::new();
        for other in std::iter::once(symbol).chain(
            section
                .iter()
                .copied()
                .filter(|o| o.name == symbol.name && !std::ptr::eq(*o, symbol)),
        ) {
            match &other.mux {
                Some((_, value)) => groups.push((*value, &other.signals)),
                None => self.problem(
                    other.at,
                    format!(
                        "symbol {} is multiplexed but this section of it has no Mux=",
                        other.name
                    ),
                    "its signals skipped",
                )?,
            }
        }
        let mut values: Vec<u64> = groups.iter().map(|(v, _)| *v).collect();
        values.sort_unstable();
        values.dedup();
        let mut merged: Vec<(Signal, Vec<u64>)> = Vec::new();
        for (value, signals) in &groups {
            for s in signals.iter() {
                match merged.iter_mut().find(|(m, _)| same_layout(m, s)) {
                    Some((_, in_groups)) => {
                        if !in_groups.contains(value) {
                            in_groups.push(*value);
                        }
                    }
                    None => merged.push((s.clone(), vec![*value])),
                }
            }
        }
        for (_, in_groups) in &mut merged {
            in_groups.sort_unstable();
        }
        let all_groups: Vec<&[u64]> = merged.iter().map(|(_, g)| g.as_slice()).collect();
        let common = common_is_none(&values, &all_groups);
        let mut out = vec![multiplexor.clone()];
        for (mut s, in_groups) in merged {
            set_groups(&mut s, &multiplexor.name, &in_groups, values.len(), common);
            out.push(s);
        }
        Ok(out)
    }
}

/// Make `s` present for the multiplexor values `in_groups` of `all` values there are.
/// A signal in every group is an ordinary signal when `common_is_none`.
fn set_groups(s: &mut Signal, switch: &str, in_groups: &[u64], all: usize, common_is_none: bool) {
    match in_groups {
        _ if common_is_none && in_groups.len() == all => s.multiplexing = Multiplexing::None,
        [one] => s.multiplexing = Multiplexing::Multiplexed(*one),
        [first, ..] => {
            s.multiplexing = Multiplexing::Multiplexed(*first);
            let mut ranges: Vec<(u64, u64)> = Vec::new();
            for &v in in_groups {
                match ranges.last_mut() {
                    Some((_, hi)) if hi.checked_add(1) == Some(v) => *hi = v,
                    _ => ranges.push((v, v)),
                }
            }
            s.mux_condition = Some(MuxCondition {
                switch: switch.to_string(),
                ranges,
            });
        }
        [] => {}
    }
}

/// Whether the signals in every group can be ordinary signals: only when each value also
/// selects a signal of its own, so that the values the multiplexor may take stay known (a
/// frame with any other value does not decode).
fn common_is_none(values: &[u64], groups: &[&[u64]]) -> bool {
    values.len() >= 2
        && values.iter().all(|v| {
            groups
                .iter()
                .any(|g| g.len() < values.len() && g.contains(v))
        })
}

/// Two placements of one signal: equal but for their multiplexing and where they were read.
fn same_layout(a: &Signal, b: &Signal) -> bool {
    let mut b = b.clone();
    b.multiplexing = a.multiplexing;
    b.mux_condition.clone_from(&a.mux_condition);
    a == &b
}

fn split_outside_quotes(text: &str, separator: char) -> Vec<&str> {
    let mut out = Vec::new();
    let mut quoted = false;
    let mut begin = 0;
    let mut previous = '\0';
    for (i, c) in text.char_indices() {
        if c == '"' && previous != '\\' {
            quoted = !quoted;
        } else if c == separator && !quoted {
            out.push(text.get(begin..i).unwrap_or_default());
            begin = i + c.len_utf8();
        }
        previous = c;
    }
    out.push(text.get(begin..).unwrap_or_default());
    out
}

/// A physical default as the raw start value DBC keeps (`GenSigStartValue`).
fn raw_of_physical(s: &Signal, physical: Num) -> Option<Num> {
    let factor = s.factor.as_f64();
    if factor == 0.0 {
        return None;
    }
    let raw = (physical.as_f64() - s.offset.as_f64()) / factor;
    let nearest = raw.round();
    Some(
        if (raw - nearest).abs() < 1e-6 * nearest.abs().max(1.0) && nearest.abs() < 9.0e15 {
            #[allow(clippy::cast_possible_truncation)]
            Num::Int(nearest as i128)
        } else {
            Num::Float(raw)
        },
    )
}

/// A raw start value as the physical default SYM writes.
fn physical_of_raw(s: &Signal, raw: Num) -> Num {
    let physical = raw.as_f64() * s.factor.as_f64() + s.offset.as_f64();
    if physical.fract() == 0.0 && physical.abs() < 9.0e15 {
        #[allow(clippy::cast_possible_truncation)]
        Num::Int(physical as i128)
    } else {
        Num::Float(physical)
    }
}

/// Where a message's section goes.
fn section_of(m: &Message) -> Section {
    match (m.transmitter.as_str(), m.senders.as_slice()) {
        (SENDER, []) => Section::Send,
        (RECEIVER, []) => Section::Receive,
        _ => Section::SendReceive,
    }
}

/// `db` reduced to what SYM says.
pub(crate) fn expressible(db: &Database) -> (Database, Vec<Omission>) {
    let (out, omissions, _) = reduce(db);
    (out, omissions)
}

/// `db` reduced to what SYM says, what that dropped, and each message's multiplexor values
/// (a value may select only the signals every value selects, so the signals alone do not tell).
fn reduce(db: &Database) -> (Database, Vec<Omission>, Vec<Vec<u64>>) {
    let mut omissions = Omissions::default();
    // In the order the reader gives them: `/ln:` and `/spn:` as written, the start value last.
    let kept = [attrs::LONG_NAME, attrs::SPN, attrs::START_VALUE];
    let family = [
        attrs::CYCLE_TIME,
        attrs::FRAME_FORMAT,
        attrs::LONG_NAME,
        attrs::SPN,
        attrs::START_VALUE,
    ];
    let mut out = keep_attributes(db, &family, &mut omissions, |db, m| {
        let mut list = Vec::new();
        if let Some(ms) = cycle_time_ms(db, m) {
            list.push((
                attrs::CYCLE_TIME.to_string(),
                AttrValue::Number(Num::Int(i128::from(ms))),
            ));
        }
        if db.fd_format(m).0 {
            list.push((
                attrs::FRAME_FORMAT.to_string(),
                AttrValue::Number(Num::Int(if m.extended { 3 } else { 2 })),
            ));
        }
        list
    });
    drop_dbc_only(&mut out, &mut omissions);
    let no_brs = db
        .messages
        .iter()
        .filter(|m| db.fd_format(m) == (true, false))
        .count();
    if no_brs > 0 {
        omissions.add(format!(
            "CAN FD without bit rate switching on {no_brs} messages"
        ));
    }
    if !out.nodes.is_empty() {
        omissions.add(format!(
            "{} nodes (SYM knows only messages sent, received or both)",
            out.nodes.len()
        ));
        out.nodes.clear();
    }
    if !out.version.is_empty() && out.version != "6.0" {
        omissions.add(format!("the version {}", out.version));
    }
    out.version = "6.0".into();
    if out
        .comment
        .as_deref()
        .is_some_and(|c| c.contains(['\n', '"']))
    {
        omissions.add("line breaks and quotes in the network comment");
    }
    out.comment = out
        .comment
        .map(|c| one_line(&c).replace('"', "'"))
        .filter(|c| !c.is_empty());
    let mut re_sent = 0;
    let mut receivers = 0;
    let mut comments = 0;
    let mut values_of = Vec::with_capacity(out.messages.len());
    for m in &mut out.messages {
        let sayable = match (m.transmitter.as_str(), m.senders.as_slice()) {
            (SENDER | RECEIVER, []) => true,
            (SENDER, [other]) => other == RECEIVER,
            _ => false,
        };
        if !sayable {
            re_sent += 1;
            m.transmitter = SENDER.into();
            m.senders = vec![RECEIVER.into()];
        }
        comments += usize::from(m.comment.as_deref().is_some_and(|c| c.contains('\n')));
        m.comment = m.comment.as_deref().map(one_line).filter(|c| !c.is_empty());
        for s in &mut m.signals {
            if s.receivers.iter().any(|r| r != NO_NODE) {
                receivers += 1;
            }
            s.receivers = vec![NO_NODE.to_string()];
            comments += usize::from(s.comment.as_deref().is_some_and(|c| c.contains('\n')));
            s.comment = s.comment.as_deref().map(one_line).filter(|c| !c.is_empty());
            if let Some(at) = s
                .attributes
                .iter()
                .position(|(n, _)| n == attrs::START_VALUE)
            {
                let raw = match s.attributes.get(at) {
                    Some((_, AttrValue::Number(n))) => raw_of_physical(s, physical_of_raw(s, *n)),
                    _ => None,
                };
                match raw {
                    Some(raw) => {
                        if let Some(slot) = s.attributes.get_mut(at) {
                            slot.1 = AttrValue::Number(raw);
                        }
                    }
                    None => {
                        s.attributes.remove(at);
                    }
                }
            }
            s.attributes.retain(|(n, v)| match v {
                AttrValue::Number(Num::Int(_)) => true,
                AttrValue::Number(_) => n != attrs::SPN && n != attrs::LONG_NAME,
                AttrValue::Str(_) => n == attrs::LONG_NAME,
            });
            s.attributes
                .sort_by_key(|(n, _)| kept.iter().position(|k| k == n));
        }
        values_of.push(multiplexing(m, &mut omissions));
    }
    if re_sent > 0 {
        omissions.add(format!("the senders of {re_sent} messages (SYM says only sent, received or both; written as both)"));
    }
    if receivers > 0 {
        omissions.add(format!("the receivers of {receivers} signals"));
    }
    if comments > 0 {
        omissions.add(format!("line breaks in {comments} comments"));
    }
    let order = |m: &Message| match section_of(m) {
        Section::Send => 0,
        Section::Receive => 1,
        _ => 2,
    };
    let mut paired: Vec<(Message, Vec<u64>)> = out.messages.drain(..).zip(values_of).collect();
    paired.sort_by_key(|(m, _)| order(m));
    let (messages, values_of) = paired.into_iter().unzip();
    out.messages = messages;
    attrs::define_used(&mut out);
    (out, omissions.into_vec(), values_of)
}

fn one_line(text: &str) -> String {
    text.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// A message's multiplexing reduced to one multiplexor whose values select groups of
/// signals, in the order the reader gives them back: the multiplexor, the signals present
/// for every value, then each value's own. Gives the multiplexor's values.
fn multiplexing(m: &mut Message, omissions: &mut Omissions) -> Vec<u64> {
    let Some(first) = m
        .signals
        .iter()
        .position(|s| s.multiplexing == Multiplexing::Multiplexor)
    else {
        for s in &mut m.signals {
            if s.multiplexing != Multiplexing::None || s.mux_condition.is_some() {
                omissions.add(format!(
                    "the multiplexing of signal {} in message {} (it has no multiplexor)",
                    s.name, m.name
                ));
                s.multiplexing = Multiplexing::None;
                s.mux_condition = None;
            }
        }
        return Vec::new();
    };
    let switch = m
        .signals
        .get(first)
        .map(|s| s.name.clone())
        .unwrap_or_default();
    let mut groups_of: Vec<Vec<u64>> = Vec::with_capacity(m.signals.len());
    for (i, s) in m.signals.iter_mut().enumerate() {
        if s.multiplexing == Multiplexing::Multiplexor && i != first {
            omissions.add(format!(
                "signal {} in message {} as a second multiplexor",
                s.name, m.name
            ));
            s.multiplexing = Multiplexing::None;
        }
        let groups = match (s.multiplexing, &s.mux_condition) {
            (Multiplexing::Multiplexed(v) | Multiplexing::MultiplexedMultiplexor(v), None) => {
                vec![v]
            }
            (Multiplexing::Multiplexed(_) | Multiplexing::MultiplexedMultiplexor(_), Some(c))
                if c.switch == switch
                    && c.ranges
                        .iter()
                        .map(|(a, b)| b.saturating_sub(*a).saturating_add(1))
                        .sum::<u64>()
                        <= MAX_GROUPS_PER_SIGNAL =>
            {
                c.ranges.iter().flat_map(|&(a, b)| a..=b).collect()
            }
            (Multiplexing::None | Multiplexing::Multiplexor, None) => vec![],
            _ => {
                omissions.add(format!(
                    "the multiplexing of signal {} in message {} (not by its multiplexor {switch})",
                    s.name, m.name
                ));
                vec![]
            }
        };
        if matches!(s.multiplexing, Multiplexing::MultiplexedMultiplexor(_)) {
            omissions.add(format!(
                "signal {} in message {} as a multiplexor",
                s.name, m.name
            ));
        }
        groups_of.push(groups);
    }
    let mut values: Vec<u64> = groups_of.iter().flatten().copied().collect();
    values.sort_unstable();
    values.dedup();
    if values.is_empty() {
        omissions.add(format!(
            "the multiplexor role of {switch} in message {} (it selects no signals)",
            m.name
        ));
    }
    let own: Vec<&[u64]> = groups_of
        .iter()
        .filter(|g| !g.is_empty())
        .map(Vec::as_slice)
        .collect();
    let common = common_is_none(&values, &own);
    let mut placed: Vec<(Signal, usize)> = Vec::new();
    for (i, (mut s, groups)) in m.signals.drain(..).zip(groups_of).enumerate() {
        s.mux_condition = None;
        let rank = if i == first {
            let mut bare = plain_signal(
                s.name.clone(),
                (s.start_bit, s.length, s.byte_order),
                s.multiplexing,
                s.position,
            );
            bare.comment.clone_from(&s.comment);
            if !values.is_empty() && s != bare {
                omissions.add(format!(
                    "the sign, scaling, range, unit, value names and attributes of multiplexor {} in message {} (a Mux= has none)",
                    s.name, m.name
                ));
                s = bare;
            }
            if values.is_empty() {
                s.multiplexing = Multiplexing::None;
                placed.push((s, 1));
                continue;
            }
            s.multiplexing = Multiplexing::Multiplexor;
            0
        } else if groups.is_empty() {
            set_groups(&mut s, &switch, &values, values.len(), common);
            if values.is_empty() {
                s.multiplexing = Multiplexing::None;
            }
            1
        } else {
            set_groups(&mut s, &switch, &groups, values.len(), common);
            if s.multiplexing == Multiplexing::None {
                1
            } else {
                2 + groups
                    .first()
                    .and_then(|g| values.iter().position(|v| v == g))
                    .unwrap_or(0)
            }
        };
        placed.push((s, rank));
    }
    placed.sort_by_key(|(_, rank)| *rank);
    m.signals = placed.into_iter().map(|(s, _)| s).collect();
    values
}

/// A name as SYM writes it: bare when it is a plain word, else quoted.
fn name(text: &str) -> String {
    if !text.is_empty() && text.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
        text.to_string()
    } else {
        quote(text)
    }
}

fn quote(text: &str) -> String {
    format!("\"{}\"", text.replace('\\', "\\\\").replace('"', "\\\""))
}

/// `db` as SYM 6.0 text, with what SYM could not say. Every signal is written as its
/// message's own variable (`Var=`), so two signals of one name in different messages keep
/// their own scaling.
pub(crate) fn write(db: &Database) -> (String, Vec<Omission>) {
    let (db, omissions, values_of) = reduce(db);
    let mut o = String::from("FormatVersion=6.0 // Do not edit this line!\n");
    o.push_str(&format!(
        "Title={}\n",
        quote(db.comment.as_deref().unwrap_or_default())
    ));
    // Value tables, one per distinct list, named after the first signal that uses it.
    let mut enums: Vec<(String, &[(i128, String)])> = Vec::new();
    for s in db.messages.iter().flat_map(|m| &m.signals) {
        if s.value_descriptions.is_empty()
            || enums
                .iter()
                .any(|(_, v)| *v == s.value_descriptions.as_slice())
        {
            continue;
        }
        let base: String = s
            .name
            .chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || c == '_' {
                    c
                } else {
                    '_'
                }
            })
            .collect();
        let mut candidate = base.clone();
        let mut n = 1;
        while enums.iter().any(|(e, _)| *e == candidate) {
            n += 1;
            candidate = format!("{base}_{n}");
        }
        enums.push((candidate, &s.value_descriptions));
    }
    if !enums.is_empty() {
        o.push_str("\n{ENUMS}\n");
        for (enum_name, values) in &enums {
            let list: Vec<String> = values
                .iter()
                .map(|(v, d)| format!("{v}={}", quote(d)))
                .collect();
            o.push_str(&format!("Enum={enum_name}({})\n", list.join(", ")));
        }
    }
    let enum_of = |s: &Signal| {
        enums
            .iter()
            .find(|(_, v)| *v == s.value_descriptions.as_slice())
            .map(|(n, _)| n.as_str())
    };
    let mut current: Option<Section> = None;
    for (m, values) in db.messages.iter().zip(&values_of) {
        let section = section_of(m);
        if current != Some(section) {
            o.push_str(match section {
                Section::Send => "\n{SEND}\n",
                Section::Receive => "\n{RECEIVE}\n",
                _ => "\n{SENDRECEIVE}\n",
            });
            current = Some(section);
        }
        let multiplexor = m
            .signals
            .iter()
            .find(|s| s.multiplexing == Multiplexing::Multiplexor);
        let common: Vec<&Signal> = m
            .signals
            .iter()
            .filter(|s| s.multiplexing == Multiplexing::None)
            .collect();
        let sections: Vec<Option<u64>> = match multiplexor {
            Some(_) if !values.is_empty() => values.iter().copied().map(Some).collect(),
            _ => vec![None],
        };
        for (i, value) in sections.iter().enumerate() {
            o.push_str(&format!("\n[{}]\n", name(&m.name)));
            if i == 0 {
                let digits = if m.extended { 8 } else { 3 };
                o.push_str(&format!("ID={:0digits$X}h", m.id));
                if let Some(c) = &m.comment {
                    o.push_str(&format!(" // {c}"));
                }
                o.push('\n');
                let fd = m.attribute(attrs::FRAME_FORMAT).is_some();
                match (m.extended, fd) {
                    (false, false) => {}
                    (true, false) => o.push_str("Type=Extended\n"),
                    (false, true) => o.push_str("Type=FDStandard\n"),
                    (true, true) => o.push_str("Type=FDExtended\n"),
                }
            }
            o.push_str(&format!("Len={}\n", m.size));
            if let Some(ms) = cycle_time_ms(&db, m) {
                o.push_str(&format!("CycleTime={ms}\n"));
            }
            let in_group: Vec<&Signal> = match (value, multiplexor) {
                (Some(v), Some(mux)) => {
                    o.push_str(&format!(
                        "Mux={} {},{} {v:X}h",
                        name(&mux.name),
                        mux.network_start_bit(),
                        mux.length
                    ));
                    if mux.byte_order == ByteOrder::BigEndian {
                        o.push_str(" -m");
                    }
                    if let Some(c) = &mux.comment {
                        o.push_str(&format!(" // {c}"));
                    }
                    o.push('\n');
                    common
                        .iter()
                        .copied()
                        .chain(m.signals.iter().filter(|s| groups_of(s).contains(v)))
                        .collect()
                }
                _ => m.signals.iter().collect(),
            };
            for s in in_group {
                variable(&mut o, s, enum_of(s));
            }
        }
    }
    (o, omissions)
}

/// The multiplexor values a signal is written under.
fn groups_of(s: &Signal) -> Vec<u64> {
    match (&s.mux_condition, s.multiplexing) {
        (Some(c), _) => c.ranges.iter().flat_map(|&(a, b)| a..=b).collect(),
        (None, Multiplexing::Multiplexed(v)) => vec![v],
        _ => vec![],
    }
}

fn variable(o: &mut String, s: &Signal, enumeration: Option<&str>) {
    let kind = match s.value_type {
        ValueType::Integer { signed: false } => "unsigned",
        ValueType::Integer { signed: true } => "signed",
        ValueType::Float32 => "float",
        ValueType::Float64 => "double",
    };
    o.push_str(&format!(
        "Var={} {kind} {},{}",
        name(&s.name),
        s.network_start_bit(),
        s.length
    ));
    if s.byte_order == ByteOrder::BigEndian {
        o.push_str(" -m");
    }
    if !s.unit.is_empty() {
        o.push_str(&format!(" /u:{}", quote(&s.unit)));
    }
    if s.factor != Num::Int(1) {
        o.push_str(&format!(" /f:{}", s.factor));
    }
    if s.offset != Num::Int(0) {
        o.push_str(&format!(" /o:{}", s.offset));
    }
    if (s.minimum, s.maximum) != (Num::Int(0), Num::Int(0)) {
        o.push_str(&format!(" /min:{} /max:{}", s.minimum, s.maximum));
    }
    for (key, value) in &s.attributes {
        match (key.as_str(), value) {
            (attrs::START_VALUE, AttrValue::Number(raw)) => {
                o.push_str(&format!(" /d:{}", physical_of_raw(s, *raw)))
            }
            (attrs::LONG_NAME, AttrValue::Str(long)) => {
                o.push_str(&format!(" /ln:{}", quote(long)))
            }
            (attrs::SPN, AttrValue::Number(n)) => o.push_str(&format!(" /spn:{n}")),
            _ => {}
        }
    }
    if let Some(e) = enumeration {
        o.push_str(&format!(" /e:{e}"));
    }
    if let Some(c) = &s.comment {
        o.push_str(&format!(" // {c}"));
    }
    o.push('\n');
}

#[cfg(test)]
mod tests {
    use super::*;

    const SYM: &str = r#"FormatVersion=6.0 // Do not edit this line!
Title="Test"

{ENUMS}
Enum=Gear(0="Park", 1="Drive",
  2="Reverse")

{SIGNALS}
Sig=Speed unsigned 16 /u:"km/h" /f:0.01 /max:650 // vehicle speed
Sig=Flag bit

{SEND}
[Status]
ID=123h // status frame
Len=4
CycleTime=20
Sig=Speed 0
Var=Gear Gear 16,2 /d:1

{SENDRECEIVE}
[Paged]
ID=00000400h-00000401h
Len=8
Mux=Page 0,8 1
Var=A signed 8,8 -m
Sig=Flag 20

[Paged]
Len=8
Mux=Page 0,8 2
Var=B unsigned 8,8
Sig=Flag 20
"#;

    #[test]
    fn reads_enums_signals_ranges_and_multiplexed_sections() {
        let (db, diagnostics) = read(SYM, Mode::Strict).unwrap();
        assert!(diagnostics.is_empty(), "{diagnostics:?}");
        assert_eq!(db.messages.len(), 3);
        let status = &db.messages[0];
        assert_eq!(
            (status.id, status.size, status.transmitter.as_str()),
            (0x123, 4, "ECU")
        );
        assert_eq!(status.comment.as_deref(), Some("status frame"));
        let speed = status.signal("Speed").unwrap();
        assert_eq!(
            (speed.factor, speed.unit.as_str()),
            (Num::Float(0.01), "km/h")
        );
        assert_eq!(speed.comment.as_deref(), Some("vehicle speed"));
        let gear = status.signal("Gear").unwrap();
        assert_eq!(gear.value_descriptions.len(), 3);
        assert_eq!(
            gear.attributes,
            [(
                attrs::START_VALUE.to_string(),
                AttrValue::Number(Num::Int(1))
            )]
        );
        let paged = &db.messages[1];
        assert!(paged.extended);
        assert_eq!(db.messages[2].id, 0x401);
        assert_eq!(
            paged.signal("Page").unwrap().multiplexing,
            Multiplexing::Multiplexor
        );
        assert_eq!(
            paged.signal("A").unwrap().multiplexing,
            Multiplexing::Multiplexed(1)
        );
        assert_eq!(paged.signal("A").unwrap().start_bit, 15);
        assert_eq!(
            paged.signal("B").unwrap().multiplexing,
            Multiplexing::Multiplexed(2)
        );
        assert_eq!(
            paged.signal("Flag").unwrap().multiplexing,
            Multiplexing::None
        );
    }

    #[test]
    fn written_sym_reads_back_as_what_sym_can_say() {
        let (db, _) = read(SYM, Mode::Strict).unwrap();
        let (text, omissions) = write(&db);
        assert!(omissions.is_empty(), "{omissions:?}");
        let (back, _) = read(&text, Mode::Strict).unwrap();
        assert_eq!(back, expressible(&db).0, "{text}");
    }

    #[test]
    fn bad_files_get_a_positioned_error() {
        assert!(read("Title=\"x\"\n", Mode::Lenient).is_err());
        let bad = SYM.replace("Sig=Speed 0", "Sig=Speeed 0");
        let (db, diagnostics) = read(&bad, Mode::Lenient).unwrap();
        assert_eq!(diagnostics.len(), 1, "{diagnostics:?}");
        assert_eq!(diagnostics[0].line, 17);
        assert!(db.messages[0].signal("Speed").is_none());
        let e = read(&bad, Mode::Strict).unwrap_err();
        assert!(e.0.message.contains("Speeed"), "{e}");
        let huge = SYM.replace("00000400h-00000401h", "00000000h-1FFFFFFFh");
        let (db, diagnostics) = read(&huge, Mode::Lenient).unwrap();
        assert_eq!(db.messages.len(), 1);
        assert!(diagnostics[0].message.contains("range"), "{diagnostics:?}");
    }
}
