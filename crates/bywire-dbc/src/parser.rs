//! The DBC parser: lenient (the model plus one diagnostic per problem) or strict (the first
//! problem is an error).

use std::fmt;

use crate::lexer::{tokenize, Tok, Token};
use crate::model::*;

/// How strictly to read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Mode {
    /// Accept what a reasonable engineer would, report every problem and how it was resolved.
    Lenient,
    /// Fail on the first problem.
    Strict,
}

/// How bad a problem is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Severity {
    /// Worth knowing (lint only).
    Info,
    /// Not standard, but unambiguous.
    Warning,
    /// Something was dropped or guessed.
    Error,
}

/// One problem in a file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Diagnostic {
    /// 1-based line.
    pub line: u32,
    /// 1-based column.
    pub column: u32,
    /// How bad.
    pub severity: Severity,
    /// What is wrong.
    pub message: String,
    /// What the lenient parser did about it.
    pub resolution: String,
}

impl fmt::Display for Diagnostic {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let sev = match self.severity {
            Severity::Info => "info",
            Severity::Warning => "warning",
            Severity::Error => "error",
        };
        write!(
            f,
            "{}:{}: {sev}: {} ({})",
            self.line, self.column, self.message, self.resolution
        )
    }
}

/// A file that cannot be read at all, or, in strict mode, its first problem.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct ParseError(pub Diagnostic);

/// Parse DBC bytes (UTF-8, or cp1252 when not valid UTF-8).
pub fn parse(bytes: &[u8], mode: Mode) -> Result<(Database, Vec<Diagnostic>), ParseError> {
    parse_str(&crate::format::text_of(bytes), mode)
}

/// Parse DBC text.
pub fn parse_str(text: &str, mode: Mode) -> Result<(Database, Vec<Diagnostic>), ParseError> {
    let mut p = Parser {
        text,
        toks: tokenize(text),
        pos: 0,
        diags: Vec::new(),
        db: Database::default(),
        pending: Pending::default(),
        message_ids: std::collections::HashMap::new(),
    };
    p.run();
    p.resolve();
    p.check_layout();
    if mode == Mode::Strict {
        if let Some(first) = p.diags.first() {
            return Err(ParseError(first.clone()));
        }
    }
    Ok((p.db, p.diags))
}

type ValueDescriptions = Vec<(i128, String)>;

/// Object references collected while reading, attached once every message is known.
#[derive(Default)]
struct Pending {
    comments: Vec<(Target, String, Token)>,
    attributes: Vec<(Target, String, AttrValue, Token)>,
    values: Vec<(Target, ValueDescriptions, Token)>,
    valtypes: Vec<(u32, String, u8, Token)>,
    mux_vals: Vec<(u32, String, MuxCondition, Token)>,
    senders: Vec<(u32, Vec<String>, Token)>,
}

#[derive(Debug, Clone, PartialEq)]
enum Target {
    Network,
    Node(String),
    Message(u32),
    Signal(u32, String),
    EnvVar(String),
}

/// Vector's pseudo-message that holds signals not assigned to any message.
pub const INDEPENDENT_SIGNALS: &str = "VECTOR__INDEPENDENT_SIG_MSG";

const KEYWORDS: &[&str] = &[
    "VERSION",
    "NS_",
    "BS_",
    "BU_",
    "VAL_TABLE_",
    "BO_",
    "SG_",
    "BO_TX_BU_",
    "EV_",
    "CM_",
    "BA_DEF_",
    "BA_DEF_DEF_",
    "BA_",
    "VAL_",
    "SIG_GROUP_",
    "SIG_VALTYPE_",
    "SG_MUL_VAL_",
    "BA_DEF_REL_",
    "BA_REL_",
    "BA_DEF_DEF_REL_",
    "BU_SG_REL_",
    "BU_EV_REL_",
    "BU_BO_REL_",
    "ENVVAR_DATA_",
    "SGTYPE_",
    "SGTYPE_VAL_",
    "SIG_TYPE_REF_",
    "CAT_DEF_",
    "CAT_",
    "FILTER",
    "EV_DATA_",
    "SIGTYPE_VALTYPE_",
];

struct Parser<'a> {
    text: &'a str,
    toks: Vec<Token>,
    pos: usize,
    diags: Vec<Diagnostic>,
    db: Database,
    pending: Pending,
    /// Each (identifier, extended) to the first message that has it: duplicates found and
    /// references resolved in constant time (a linear search made loading quadratic).
    message_ids: std::collections::HashMap<(u32, bool), usize>,
}

type Step<T> = Result<T, Diagnostic>;

impl Parser<'_> {
    fn peek(&self) -> Option<&Token> {
        self.toks.get(self.pos)
    }

    fn here(&self) -> Token {
        self.peek().cloned().unwrap_or_else(|| {
            let (line, col) = self.toks.last().map_or((1, 1), |t| (t.line, t.col + 1));
            Token {
                tok: Tok::Punct(';'),
                line,
                col,
                start: self.text.len(),
                end: self.text.len(),
                line_start: true,
            }
        })
    }

    fn error_at(&self, t: &Token, message: impl Into<String>, resolution: &str) -> Diagnostic {
        Diagnostic {
            line: t.line,
            column: t.col,
            severity: Severity::Error,
            message: message.into(),
            resolution: resolution.into(),
        }
    }

    fn warn(&mut self, t: &Token, message: impl Into<String>, resolution: &str) {
        let mut d = self.error_at(t, message, resolution);
        d.severity = Severity::Warning;
        self.diags.push(d);
    }

    fn expected(&self, what: &str) -> Diagnostic {
        let t = self.here();
        let found = match &t.tok {
            Tok::Ident { text, .. } => format!("'{text}'"),
            Tok::Number(n) => format!("number {n}"),
            Tok::Str(_) => "a string".into(),
            Tok::Punct(c) | Tok::Unexpected(c) if self.peek().is_some() => format!("'{c}'"),
            _ => "end of file".into(),
        };
        self.error_at(
            &t,
            format!("expected {what}, found {found}"),
            "statement skipped",
        )
    }

    fn next(&mut self) -> Option<Token> {
        let t = self.toks.get(self.pos).cloned();
        self.pos += 1;
        t
    }

    fn punct(&mut self, c: char) -> Step<()> {
        match self.peek().map(|t| &t.tok) {
            Some(Tok::Punct(p)) if *p == c => {
                self.pos += 1;
                Ok(())
            }
            _ => Err(self.expected(&format!("'{c}'"))),
        }
    }

    fn eat_punct(&mut self, c: char) -> bool {
        self.punct(c).is_ok()
    }

    /// A name; lenient about names starting with a digit.
    fn name(&mut self) -> Step<String> {
        let t = self.here();
        match &t.tok {
            Tok::Ident { text, digit_start } => {
                let text = text.clone();
                if *digit_start {
                    self.warn(
                        &t,
                        format!("name '{text}' starts with a digit"),
                        "name kept",
                    );
                }
                self.pos += 1;
                Ok(text)
            }
            _ => Err(self.expected("a name")),
        }
    }

    fn number(&mut self) -> Step<Num> {
        let t = self.here();
        match &t.tok {
            Tok::Number(n) => {
                let n = n.clone();
                self.pos += 1;
                if let Some((sign, fraction)) = ["", "-", "+"]
                    .iter()
                    .find_map(|sign| Some((*sign, n.strip_prefix(sign)?.strip_prefix('.')?)))
                {
                    self.warn(
                        &t,
                        format!("number '{n}' has no digit before the point"),
                        &format!("read as {}0.{fraction}", sign.trim_start_matches('+')),
                    );
                }
                parse_num(&n).ok_or_else(|| {
                    self.error_at(&t, format!("'{n}' is not a number"), "statement skipped")
                })
            }
            _ => Err(self.expected("a number")),
        }
    }

    fn integer(&mut self) -> Step<i128> {
        let t = self.here();
        match self.number()? {
            Num::Int(i) => Ok(i),
            Num::Float(f) => Err(self.error_at(
                &t,
                format!("expected an integer, found {f}"),
                "statement skipped",
            )),
        }
    }

    fn unsigned(&mut self, what: &str) -> Step<u32> {
        let t = self.here();
        let v = self.integer()?;
        u32::try_from(v).map_err(|_| {
            self.error_at(
                &t,
                format!("{what} {v} is out of range"),
                "statement skipped",
            )
        })
    }

    fn string(&mut self) -> Step<String> {
        match self.peek().map(|t| t.tok.clone()) {
            Some(Tok::Str(s)) => {
                self.pos += 1;
                Ok(s)
            }
            _ => Err(self.expected("a string")),
        }
    }

    /// Skip to the next statement: a keyword at the start of a line.
    fn recover(&mut self) {
        while let Some(t) = self.peek() {
            if t.line_start
                && matches!(&t.tok, Tok::Ident { text, .. } if KEYWORDS.contains(&text.as_str()))
            {
                break;
            }
            self.pos += 1;
        }
    }

    /// The end of a `;`-terminated statement; lenient about a missing `;` at the end of a line.
    fn end(&mut self) -> Step<()> {
        if self.eat_punct(';') {
            return Ok(());
        }
        let t = self.here();
        if self.peek().is_none() || t.line_start {
            self.warn(
                &t,
                "missing ';' at the end of the statement",
                "statement ended at the line end",
            );
            return Ok(());
        }
        Err(self.expected("';'"))
    }

    fn run(&mut self) {
        while let Some(t) = self.peek().cloned() {
            let statement_at = self.pos;
            let result = match &t.tok {
                Tok::Ident { text, .. } => {
                    let kw = text.clone();
                    self.pos += 1;
                    self.statement(&kw, &t)
                }
                _ => Err(self.expected("a keyword such as BO_ or SG_")),
            };
            if let Err(d) = result {
                self.diags.push(d);
                self.pos = self.pos.max(statement_at + 1);
                self.recover();
            }
        }
    }

    fn statement(&mut self, kw: &str, at: &Token) -> Step<()> {
        match kw {
            "VERSION" => {
                self.db.version = self.string()?;
                Ok(())
            }
            "NS_" => self.new_symbols(),
            "BS_" => self.bit_timing(at),
            "BU_" => self.nodes(),
            "VAL_TABLE_" => {
                let name = self.name()?;
                let pairs = self.value_pairs()?;
                self.db.value_tables.push((name, pairs));
                Ok(())
            }
            "BO_" => self.message(at),
            "SG_" => self.signal(at),
            "BO_TX_BU_" => {
                let id = self.unsigned("message id")?;
                self.punct(':')?;
                let mut senders = vec![self.name()?];
                while self.eat_punct(',') {
                    senders.push(self.name()?);
                }
                self.end()?;
                self.pending.senders.push((id, senders, at.clone()));
                Ok(())
            }
            "EV_" => self.env_var(),
            "CM_" => self.comment(at),
            "BA_DEF_" => self.attribute_def(),
            "BA_DEF_DEF_" => {
                let name = self.string()?;
                let value = self.attr_value()?;
                self.end()?;
                match self.db.attribute_defs.iter_mut().find(|d| d.name == name) {
                    Some(d) => d.default = Some(value),
                    None => self.diags.push(self.error_at(
                        at,
                        format!("default for undefined attribute \"{name}\""),
                        "ignored",
                    )),
                }
                Ok(())
            }
            "BA_" => {
                let name = self.string()?;
                let target = self.target(false)?;
                let value = self.attr_value()?;
                self.end()?;
                self.pending
                    .attributes
                    .push((target, name, value, at.clone()));
                Ok(())
            }
            "VAL_" => {
                let t = self.here();
                let target = match &t.tok {
                    Tok::Number(_) => {
                        let id = self.unsigned("message id")?;
                        Target::Signal(id, self.name()?)
                    }
                    _ => Target::EnvVar(self.name()?),
                };
                let pairs = self.value_pairs()?;
                self.pending.values.push((target, pairs, at.clone()));
                Ok(())
            }
            "SIG_GROUP_" => self.signal_group(),
            "SIG_VALTYPE_" => {
                let id = self.unsigned("message id")?;
                let name = self.name()?;
                self.eat_punct(':');
                let t = self.here();
                let kind = self.unsigned("value type")?;
                self.end()?;
                let kind = u8::try_from(kind).unwrap_or(u8::MAX);
                self.pending.valtypes.push((id, name, kind, t));
                Ok(())
            }
            "SG_MUL_VAL_" => self.mux_values(at),
            _ => self.unknown(kw, at),
        }
    }

    /// `NS_`: the new symbols, up to the next statement.
    fn new_symbols(&mut self) -> Step<()> {
        self.eat_punct(':');
        while let Some(t) = self.peek() {
            if t.line_start && t.col == 1 {
                break;
            }
            if let Tok::Ident { text, .. } = &t.tok {
                let s = text.clone();
                self.db.new_symbols.push(s);
            }
            self.pos += 1;
        }
        Ok(())
    }

    /// `BS_`: the baudrate and BTR values, kept as written.
    fn bit_timing(&mut self, at: &Token) -> Step<()> {
        self.eat_punct(':');
        let start = self.peek().map(|t| t.start);
        let mut has_string = false;
        while let Some(t) = self.peek().filter(|t| !t.line_start) {
            has_string |= matches!(t.tok, Tok::Str(_));
            self.pos += 1;
        }
        let end = self.toks.get(self.pos.saturating_sub(1)).map(|t| t.end);
        let (Some(s), Some(e)) = (start, end) else {
            return Ok(());
        };
        let content = self.text.get(s..e).unwrap_or("").trim();
        // BS_ holds a baudrate and BTR values: numbers on one line. Anything else would
        // not survive being written back, so it is reported and dropped.
        if has_string || content.contains('\n') {
            return Err(self.error_at(
                at,
                "BS_ holds text other than a baudrate and BTR values",
                "BS_ content dropped",
            ));
        }
        if e > s {
            self.db.bit_timing = content.to_string();
        }
        Ok(())
    }

    /// `BU_`: the nodes.
    fn nodes(&mut self) -> Step<()> {
        self.eat_punct(':');
        // Names on the line, and on indented lines after it (some files list one node
        // a line); a keyword, or a word at the start of a line, begins the next statement.
        let continues = |t: &Token| {
            !t.line_start
                || (t.col > 1
                    && matches!(&t.tok, Tok::Ident { text, .. } if !KEYWORDS.contains(&text.as_str())))
        };
        while self.peek().is_some_and(continues) {
            let name = self.name()?;
            self.db.nodes.push(Node {
                name,
                comment: None,
                attributes: Vec::new(),
            });
        }
        Ok(())
    }

    /// `EV_`: an environment variable, its definition kept as written.
    fn env_var(&mut self) -> Step<()> {
        let name = self.name()?;
        self.punct(':')?;
        let start = self.here().start;
        while !self.eat_punct(';') {
            if self.next().is_none() {
                return Err(self.expected("';'"));
            }
        }
        let end = self.toks.get(self.pos - 1).map_or(start, |t| t.start);
        self.db.env_vars.push(EnvVar {
            name,
            definition: self.text.get(start..end).unwrap_or("").trim().to_string(),
            comment: None,
            attributes: Vec::new(),
            value_descriptions: Vec::new(),
        });
        Ok(())
    }

    /// `SIG_GROUP_`: a signal group.
    fn signal_group(&mut self) -> Step<()> {
        let message_raw_id = self.unsigned("message id")?;
        let name = self.name()?;
        let repetitions = self.unsigned("repetitions")?;
        self.punct(':')?;
        let mut signals = Vec::new();
        while !self.eat_punct(';') {
            if self.peek().is_none_or(|t| t.line_start) {
                let t = self.here();
                self.warn(
                    &t,
                    "missing ';' at the end of the statement",
                    "statement ended at the line end",
                );
                break;
            }
            self.eat_punct(',');
            signals.push(self.name()?);
        }
        self.db.signal_groups.push(SignalGroup {
            message_raw_id,
            name,
            repetitions,
            signals,
        });
        Ok(())
    }

    /// `SG_MUL_VAL_`: the multiplexor values that select a signal.
    fn mux_values(&mut self, at: &Token) -> Step<()> {
        let id = self.unsigned("message id")?;
        let name = self.name()?;
        let switch = self.name()?;
        let mut ranges = Vec::new();
        loop {
            let lo = self.range_bound()?;
            let hi = if self.eat_punct('-') {
                self.range_bound()?
            } else {
                // "0-3" lexes as 0 and -3
                let t = self.here();
                match self.number()? {
                    Num::Int(n) if n <= 0 => u64::try_from(-n)
                        .map_err(|_| self.error_at(&t, "bad range", "statement skipped"))?,
                    _ => {
                        return Err(self.error_at(
                            &t,
                            "expected a range such as 2-5",
                            "statement skipped",
                        ))
                    }
                }
            };
            ranges.push((lo, hi));
            if !self.eat_punct(',') {
                break;
            }
        }
        self.end()?;
        self.pending
            .mux_vals
            .push((id, name, MuxCondition { switch, ranges }, at.clone()));
        Ok(())
    }

    fn range_bound(&mut self) -> Step<u64> {
        let t = self.here();
        let v = self.integer()?;
        u64::try_from(v).map_err(|_| {
            self.error_at(
                &t,
                format!("range bound {v} is negative"),
                "statement skipped",
            )
        })
    }

    /// Keep a statement this parser does not interpret, verbatim: up to its `;`, or up to the
    /// next line that starts with a keyword, or with any name in column 1 (where the writer puts
    /// every statement, so that what was one statement stays one on reload).
    fn unknown(&mut self, kw: &str, at: &Token) -> Step<()> {
        let known = KEYWORDS.contains(&kw);
        while let Some(t) = self.peek() {
            let starts_statement = t.line_start
                && match &t.tok {
                    Tok::Ident { text, .. } => KEYWORDS.contains(&text.as_str()) || t.col == 1,
                    _ => false,
                };
            if starts_statement {
                break;
            }
            let semicolon = t.tok == Tok::Punct(';');
            self.pos += 1;
            if semicolon {
                break;
            }
        }
        let end = self
            .toks
            .get(self.pos.saturating_sub(1))
            .map_or(at.end, |t| t.end);
        let raw = self
            .text
            .get(at.start..end)
            .unwrap_or("")
            .trim()
            .to_string();
        if !known {
            self.warn(at, format!("unknown statement '{kw}'"), "kept verbatim");
        }
        self.db.unknown.push(raw);
        Ok(())
    }

    fn value_pairs(&mut self) -> Step<Vec<(i128, String)>> {
        let mut pairs = Vec::new();
        while let Some(Tok::Number(_)) = self.peek().map(|t| &t.tok) {
            let t = self.here();
            let v = match self.number()? {
                Num::Int(i) => i,
                Num::Float(f) if f.fract() == 0.0 && f.abs() < 1e30 => {
                    // Written as 1.0: a whole number all the same.
                    #[allow(clippy::cast_possible_truncation)]
                    let i = f as i128;
                    self.warn(
                        &t,
                        format!("value {f} written with a fraction"),
                        "read as an integer",
                    );
                    i
                }
                Num::Float(f) => {
                    return Err(self.error_at(
                        &t,
                        format!("value {f} is not an integer"),
                        "statement skipped",
                    ));
                }
            };
            pairs.push((v, self.string()?));
        }
        self.end()?;
        Ok(pairs)
    }

    fn target(&mut self, for_comment: bool) -> Step<Target> {
        let t = self.here();
        let Tok::Ident { text, .. } = &t.tok else {
            if for_comment {
                if let Tok::Number(_) = &t.tok {
                    let id = self.unsigned("message id")?;
                    self.warn(
                        &t,
                        "comment for a message without 'BO_'",
                        "taken as a message comment",
                    );
                    return Ok(Target::Message(id));
                }
            }
            return Ok(Target::Network);
        };
        let kw = text.clone();
        Ok(match kw.as_str() {
            "BU_" => {
                self.pos += 1;
                Target::Node(self.name()?)
            }
            "BO_" => {
                self.pos += 1;
                Target::Message(self.unsigned("message id")?)
            }
            "SG_" => {
                self.pos += 1;
                let id = self.unsigned("message id")?;
                if for_comment && matches!(self.peek().map(|t| &t.tok), Some(Tok::Str(_))) {
                    return Err(self.error_at(
                        &t,
                        "signal comment without a signal name",
                        "comment dropped",
                    ));
                }
                Target::Signal(id, self.name()?)
            }
            "EV_" => {
                self.pos += 1;
                Target::EnvVar(self.name()?)
            }
            _ => Target::Network,
        })
    }

    fn comment(&mut self, at: &Token) -> Step<()> {
        let target = self.target(true)?;
        let text = self.string()?;
        self.end()?;
        self.pending.comments.push((target, text, at.clone()));
        Ok(())
    }

    fn attr_value(&mut self) -> Step<AttrValue> {
        match self.peek().map(|t| &t.tok) {
            Some(Tok::Str(_)) => Ok(AttrValue::Str(self.string()?)),
            _ => Ok(AttrValue::Number(self.number()?)),
        }
    }

    fn attribute_def(&mut self) -> Step<()> {
        let scope = match self.peek().map(|t| &t.tok) {
            Some(Tok::Ident { text, .. }) => {
                let s = match text.as_str() {
                    "BU_" => AttrScope::Node,
                    "BO_" => AttrScope::Message,
                    "SG_" => AttrScope::Signal,
                    "EV_" => AttrScope::EnvVar,
                    other => {
                        return Err(self.error_at(
                            &self.here(),
                            format!("unknown attribute scope '{other}'"),
                            "statement skipped",
                        ))
                    }
                };
                self.pos += 1;
                s
            }
            _ => AttrScope::Network,
        };
        let name = self.string()?;
        let t = self.here();
        let kind_name = self.name()?;
        let kind = match kind_name.as_str() {
            "INT" => AttrType::Int(self.number()?, self.number()?),
            "HEX" => AttrType::Hex(self.number()?, self.number()?),
            "FLOAT" => AttrType::Float(self.number()?, self.number()?),
            "STRING" => AttrType::Str,
            "ENUM" => {
                let mut values = Vec::new();
                while let Some(Tok::Str(_)) = self.peek().map(|t| &t.tok) {
                    values.push(self.string()?);
                    self.eat_punct(',');
                }
                AttrType::Enum(values)
            }
            other => {
                return Err(self.error_at(
                    &t,
                    format!("unknown attribute type '{other}'"),
                    "statement skipped",
                ))
            }
        };
        self.end()?;
        self.db.attribute_defs.push(AttrDef {
            scope,
            name,
            kind,
            default: None,
        });
        Ok(())
    }

    fn message(&mut self, at: &Token) -> Step<()> {
        let t = self.here();
        let raw = self.unsigned("message id")?;
        let name = self.name()?;
        self.punct(':')?;
        let size = self.unsigned("message size")?;
        let transmitter = if self.peek().is_some_and(|t| !t.line_start) {
            self.name()?
        } else {
            self.warn(
                at,
                format!("message {name} has no transmitter"),
                "Vector__XXX assumed",
            );
            "Vector__XXX".to_string()
        };
        let mut extended = raw & 0x8000_0000 != 0;
        let id = raw & 0x7FFF_FFFF;
        if !extended && id > 0x7FF && name != INDEPENDENT_SIGNALS {
            self.warn(
                &t,
                format!("frame id {id:#X} has more than 11 bits but no extended flag (bit 31)"),
                "taken as extended",
            );
            extended = true;
        }
        if size > 64 {
            self.diags.push(self.error_at(
                &t,
                format!("message {name} is {size} bytes long; CAN FD carries at most 64"),
                "kept as declared",
            ));
        }
        let index = self.db.messages.len();
        let duplicate = match self.message_ids.entry((id, extended)) {
            std::collections::hash_map::Entry::Occupied(_) => true,
            std::collections::hash_map::Entry::Vacant(slot) => {
                slot.insert(index);
                false
            }
        };
        if duplicate {
            self.diags.push(self.error_at(
                &t,
                format!("message id {id:#X} is defined twice"),
                "both kept; lookups find the first",
            ));
        }
        self.db.messages.push(Message {
            id,
            extended,
            name,
            size,
            transmitter,
            senders: Vec::new(),
            signals: Vec::new(),
            comment: None,
            attributes: Vec::new(),
            position: Position {
                line: at.line,
                column: at.col,
            },
        });
        Ok(())
    }

    fn signal(&mut self, at: &Token) -> Step<()> {
        let name = self.name()?;
        let mut multiplexing = Multiplexing::None;
        if let Some(Tok::Ident { text, .. }) = self.peek().map(|t| &t.tok) {
            let t = self.here();
            if text == "m" {
                self.warn(
                    &t,
                    format!("signal {name} has multiplexer indicator 'm' without a value"),
                    "read as 'M', the multiplexor",
                );
                self.pos += 1;
                multiplexing = Multiplexing::Multiplexor;
            } else {
                multiplexing = parse_mux(text).ok_or_else(|| {
                    self.error_at(
                        &t,
                        format!("'{text}' is not a multiplexer indicator (M, m3, m3M)"),
                        "signal skipped",
                    )
                })?;
                self.pos += 1;
            }
        }
        self.punct(':')?;
        let t = self.here();
        let start_bit = self.unsigned("start bit")?;
        self.punct('|')?;
        let length = self.unsigned("length")?;
        self.punct('@')?;
        let order_tok = self.here();
        let byte_order = match self.integer()? {
            0 => ByteOrder::BigEndian,
            1 => ByteOrder::LittleEndian,
            other => {
                return Err(self.error_at(
                    &order_tok,
                    format!("byte order {other} is not 0 or 1"),
                    "signal skipped",
                ))
            }
        };
        let signed = if self.eat_punct('-') {
            true
        } else {
            self.punct('+')?;
            false
        };
        self.punct('(')?;
        let factor = self.number()?;
        self.punct(',')?;
        let offset = self.number()?;
        self.punct(')')?;
        self.punct('[')?;
        let minimum = self.number()?;
        self.punct('|')?;
        let maximum = self.number()?;
        self.punct(']')?;
        let unit = self.string()?;
        let mut receivers = Vec::new();
        while self.peek().is_some_and(|t| !t.line_start) {
            if self.eat_punct(',') {
                continue;
            }
            receivers.push(self.name()?);
        }
        if receivers.is_empty() {
            self.warn(
                at,
                format!("signal {name} has no receiver"),
                "Vector__XXX assumed",
            );
            receivers.push("Vector__XXX".to_string());
        }
        if length == 0 || length > 64 {
            return Err(self.error_at(
                &t,
                format!("signal {name} is {length} bits long (1 to 64 allowed)"),
                "signal skipped",
            ));
        }
        let Some(message) = self.db.messages.last_mut() else {
            return Err(self.error_at(
                at,
                format!("signal {name} outside a message"),
                "signal skipped",
            ));
        };
        message.signals.push(Signal {
            name,
            start_bit,
            length,
            byte_order,
            value_type: ValueType::Integer { signed },
            factor,
            offset,
            minimum,
            maximum,
            unit,
            receivers,
            multiplexing,
            mux_condition: None,
            comment: None,
            attributes: Vec::new(),
            value_descriptions: Vec::new(),
            position: Position {
                line: at.line,
                column: at.col,
            },
        });
        Ok(())
    }

    /// Attach comments, attributes, value descriptions, value types and senders to their objects.
    fn resolve(&mut self) {
        let pending = std::mem::take(&mut self.pending);
        for (target, text, at) in pending.comments {
            match self.slot(&target, &at, "comment") {
                Some(Slot::Network) => self.db.comment = Some(text),
                Some(Slot::Node(i)) => set(&mut self.db.nodes, i, |n| n.comment = Some(text)),
                Some(Slot::Message(i)) => set(&mut self.db.messages, i, |m| m.comment = Some(text)),
                Some(Slot::Signal(i, j)) => {
                    set_signal(&mut self.db, i, j, |s| s.comment = Some(text))
                }
                Some(Slot::EnvVar(i)) => set(&mut self.db.env_vars, i, |e| e.comment = Some(text)),
                None => {}
            }
        }
        for (target, name, value, at) in pending.attributes {
            let entry = (name, value);
            match self.slot(&target, &at, "attribute") {
                Some(Slot::Network) => self.db.attributes.push(entry),
                Some(Slot::Node(i)) => set(&mut self.db.nodes, i, |n| n.attributes.push(entry)),
                Some(Slot::Message(i)) => {
                    set(&mut self.db.messages, i, |m| m.attributes.push(entry))
                }
                Some(Slot::Signal(i, j)) => {
                    set_signal(&mut self.db, i, j, |s| s.attributes.push(entry))
                }
                Some(Slot::EnvVar(i)) => {
                    set(&mut self.db.env_vars, i, |e| e.attributes.push(entry))
                }
                None => {}
            }
        }
        for (target, pairs, at) in pending.values {
            match self.slot(&target, &at, "value description") {
                Some(Slot::Signal(i, j)) => {
                    set_signal(&mut self.db, i, j, |s| s.value_descriptions = pairs)
                }
                Some(Slot::EnvVar(i)) => {
                    set(&mut self.db.env_vars, i, |e| e.value_descriptions = pairs)
                }
                _ => {}
            }
        }
        for (id, name, kind, at) in pending.valtypes {
            let value_type = match kind {
                0 => None,
                1 => Some(ValueType::Float32),
                2 => Some(ValueType::Float64),
                _ => {
                    self.diags.push(self.error_at(
                        &at,
                        format!("value type {kind} is not 0, 1 or 2"),
                        "ignored",
                    ));
                    continue;
                }
            };
            if let Some(Slot::Signal(i, j)) =
                self.slot(&Target::Signal(id, name), &at, "value type")
            {
                set_signal(&mut self.db, i, j, |s| {
                    if let Some(v) = value_type {
                        s.value_type = v;
                    }
                });
            }
        }
        for (id, name, condition, at) in pending.mux_vals {
            if let Some(Slot::Signal(i, j)) =
                self.slot(&Target::Signal(id, name), &at, "multiplexer condition")
            {
                set_signal(&mut self.db, i, j, |s| s.mux_condition = Some(condition));
            }
        }
        for (id, senders, at) in pending.senders {
            if let Some(Slot::Message(i)) = self.slot(&Target::Message(id), &at, "sender list") {
                set(&mut self.db.messages, i, |m| m.senders.extend(senders));
            }
        }
    }

    fn slot(&mut self, target: &Target, at: &Token, what: &str) -> Option<Slot> {
        let ids = &self.message_ids;
        let message_index = |_: &Database, raw: u32| {
            let extended = raw & 0x8000_0000 != 0;
            let id = raw & 0x7FFF_FFFF;
            // A reference without the extended bit but above 11 bits names the extended
            // message too (the first of the two in the file, as a search in order would).
            let exact = ids.get(&(id, extended)).copied();
            let wide = (!extended && id > 0x7FF)
                .then(|| ids.get(&(id, true)).copied())
                .flatten();
            [exact, wide].into_iter().flatten().min()
        };
        let found = match target {
            Target::Network => Some(Slot::Network),
            Target::Node(n) => self
                .db
                .nodes
                .iter()
                .position(|x| &x.name == n)
                .map(Slot::Node),
            Target::EnvVar(n) => self
                .db
                .env_vars
                .iter()
                .position(|x| &x.name == n)
                .map(Slot::EnvVar),
            Target::Message(raw) => message_index(&self.db, *raw).map(Slot::Message),
            Target::Signal(raw, name) => message_index(&self.db, *raw).and_then(|i| {
                self.db
                    .messages
                    .get(i)?
                    .signals
                    .iter()
                    .position(|s| &s.name == name)
                    .map(|j| Slot::Signal(i, j))
            }),
        };
        if found.is_none() {
            let object = match target {
                Target::Network => "the network".to_string(),
                Target::Node(n) => format!("node {n}"),
                Target::EnvVar(n) => format!("environment variable {n}"),
                Target::Message(raw) => format!("message {raw}"),
                Target::Signal(raw, name) => format!("signal {name} of message {raw}"),
            };
            self.diags.push(self.error_at(
                at,
                format!("{what} for {object}, which is not defined"),
                "ignored",
            ));
        }
        found
    }

    /// Layout problems a codec cannot resolve silently: signals past the end, overlaps.
    fn check_layout(&mut self) {
        self.diags.extend(layout_diagnostics(&self.db));
    }
}

/// Signals past their message's end or overlapping another, names defined twice in a message,
/// and a file without messages: the checks every format's reader makes once the database is
/// read.
pub(crate) fn layout_diagnostics(db: &Database) -> Vec<Diagnostic> {
    let mut diags = Vec::new();
    {
        let mut found: Vec<(Position, String)> = Vec::new();
        for m in db.messages.iter().filter(|m| m.name != INDEPENDENT_SIGNALS) {
            let mut used: Vec<(&Signal, BitMap)> = Vec::new();
            for s in &m.signals {
                let Some((bits, last_byte)) = signal_bits(s) else {
                    continue;
                };
                if last_byte >= m.size {
                    found.push((
                        s.position,
                        format!(
                            "signal {} of message {} runs past the message's {} bytes",
                            s.name, m.name, m.size
                        ),
                    ));
                }
                let clash = used.iter().find(|(other, other_bits)| {
                    may_coexist(other, s) && other_bits.iter().zip(&bits).any(|(a, b)| a & b != 0)
                });
                if let Some((other, _)) = clash {
                    found.push((
                        s.position,
                        format!(
                            "signals {} and {} of message {} overlap",
                            other.name, s.name, m.name
                        ),
                    ));
                }
                used.push((s, bits));
            }
        }
        let mut warnings: Vec<(Position, String, &str)> = Vec::new();
        for m in &db.messages {
            // Bounded by the message's signals (at most a few hundred).
            for (j, s) in m.signals.iter().enumerate() {
                if m.signals.iter().take(j).any(|o| o.name == s.name) {
                    warnings.push((
                        s.position,
                        format!("signal {} is defined twice in message {}", s.name, m.name),
                        "both kept; lookups by name find the first, and decoded output shows both under one name",
                    ));
                }
            }
        }
        if db.messages.iter().all(|m| m.name == INDEPENDENT_SIGNALS) {
            warnings.push((
                Position { line: 1, column: 1 },
                "the file defines no messages".to_string(),
                "loaded; there is nothing to decode",
            ));
        }
        for (at, message, resolution) in warnings {
            diags.push(Diagnostic {
                line: at.line,
                column: at.column,
                severity: Severity::Warning,
                message,
                resolution: resolution.into(),
            });
        }
        for (at, message) in found {
            diags.push(Diagnostic {
                line: at.line,
                column: at.column,
                severity: Severity::Error,
                message,
                resolution: "loaded; each signal decodes from its own bits, none past the end"
                    .into(),
            });
        }
    }
    diags
}

type BitMap = [u64; 8];

/// The absolute bits (byte × 8 + bit, bit 0 the LSB) a signal occupies within 64 bytes, and the
/// last byte it touches; `None` past 64 bytes.
pub(crate) fn signal_bits(s: &Signal) -> Option<(BitMap, u32)> {
    let mut map = [0u64; 8];
    let mut last_byte = 0;
    for pos in s.bit_positions().take(64) {
        *map.get_mut(usize::try_from(pos / 64).ok()?)? |= 1 << (pos % 64);
        last_byte = last_byte.max(pos / 8);
    }
    Some((map, last_byte))
}

/// Whether two signals can be in the same frame (not two values of one multiplexor).
pub(crate) fn may_coexist(a: &Signal, b: &Signal) -> bool {
    let value = |s: &Signal| match s.multiplexing {
        Multiplexing::Multiplexed(v) | Multiplexing::MultiplexedMultiplexor(v) => Some(v),
        Multiplexing::None | Multiplexing::Multiplexor => None,
    };
    if a.mux_condition.is_some() || b.mux_condition.is_some() {
        return false;
    }
    match (value(a), value(b)) {
        (Some(x), Some(y)) => x == y,
        _ => true,
    }
}

enum Slot {
    Network,
    Node(usize),
    Message(usize),
    Signal(usize, usize),
    EnvVar(usize),
}

fn set<T>(items: &mut [T], i: usize, f: impl FnOnce(&mut T)) {
    if let Some(item) = items.get_mut(i) {
        f(item);
    }
}

fn set_signal(db: &mut Database, i: usize, j: usize, f: impl FnOnce(&mut Signal)) {
    if let Some(s) = db.messages.get_mut(i).and_then(|m| m.signals.get_mut(j)) {
        f(s);
    }
}

fn parse_mux(text: &str) -> Option<Multiplexing> {
    if text == "M" {
        return Some(Multiplexing::Multiplexor);
    }
    let rest = text.strip_prefix('m')?;
    if let Some(n) = rest.strip_suffix('M') {
        return n.parse().ok().map(Multiplexing::MultiplexedMultiplexor);
    }
    rest.parse().ok().map(Multiplexing::Multiplexed)
}

pub(crate) fn parse_num(text: &str) -> Option<Num> {
    let t = text.strip_prefix('+').unwrap_or(text);
    if t.bytes().all(|b| b.is_ascii_digit() || b == b'-') && t.bytes().any(|b| b.is_ascii_digit()) {
        if let Ok(i) = t.parse::<i128>() {
            return Some(Num::Int(i));
        }
    }
    t.parse::<f64>()
        .ok()
        .filter(|f| f.is_finite())
        .map(Num::Float)
}
