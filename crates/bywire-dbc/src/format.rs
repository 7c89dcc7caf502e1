//! Every database format, read into the one [`Database`] model and written back from it.
//!
//! DBC is the model's native form; KCD (Kayak's XML) and SYM (PCAN Symbol Editor 6.0) map onto
//! it the way cantools maps them onto its own model, so a database converted from one to the
//! other decodes every frame to the same values. Facts a format has and DBC lacks become the
//! attributes DBC files use for them (a cycle time is `GenMsgCycleTime`, a CAN FD frame
//! `VFrameFormat`, a default `GenSigStartValue`). A writer first reduces a database to
//! what its format can say ([`expressible`]) and lists everything that reduction dropped as an
//! [`Omission`]: nothing is lost without a word.

use std::fmt;
use std::path::Path;

use crate::model::*;
use crate::parser::{Diagnostic, Mode, ParseError, Severity};

/// A database file format.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Format {
    /// Vector's DBC.
    Dbc,
    /// Kayak's KCD (XML).
    Kcd,
    /// PEAK's PCAN Symbol Editor format, version 6.0.
    Sym,
    /// An AUTOSAR system description (3.x or 4.x); read, not written.
    Arxml,
    /// A CANdela diagnostic description: its DIDs as messages; read, not written.
    Cdd,
}

impl Format {
    /// Every format, in the order `--db-format` lists them.
    pub const ALL: [Format; 5] = [
        Format::Dbc,
        Format::Kcd,
        Format::Sym,
        Format::Arxml,
        Format::Cdd,
    ];

    /// The formats bywire writes.
    pub const WRITTEN: [Format; 3] = [Format::Dbc, Format::Kcd, Format::Sym];

    /// The format's name as `--db-format` takes it, and its file extension.
    pub fn name(self) -> &'static str {
        match self {
            Format::Dbc => "dbc",
            Format::Kcd => "kcd",
            Format::Sym => "sym",
            Format::Arxml => "arxml",
            Format::Cdd => "cdd",
        }
    }

    /// Whether bywire writes this format.
    pub fn is_written(self) -> bool {
        Format::WRITTEN.contains(&self)
    }

    /// The format a name (`dbc`, `kcd`, `sym`, any case) stands for.
    pub fn from_name(name: &str) -> Option<Format> {
        Format::ALL
            .into_iter()
            .find(|f| f.name().eq_ignore_ascii_case(name))
    }

    /// The format a file's extension names.
    pub fn from_path(path: &Path) -> Option<Format> {
        Format::from_name(path.extension()?.to_str()?)
    }

    /// The format the content looks like: a KCD or AUTOSAR root element, a SYM version line,
    /// else DBC.
    pub fn sniff(bytes: &[u8]) -> Format {
        let head = bytes.get(..bytes.len().min(4096)).unwrap_or(bytes);
        let text = String::from_utf8_lossy(head);
        let body = text.trim_start_matches('\u{feff}').trim_start();
        if body.starts_with('<') && text.contains("NetworkDefinition") {
            Format::Kcd
        } else if body.starts_with('<') && text.contains("<AUTOSAR") {
            Format::Arxml
        } else if body.starts_with('<') && text.contains("<CANDELA") {
            Format::Cdd
        } else if text
            .lines()
            .any(|l| l.trim_start().starts_with("FormatVersion="))
        {
            Format::Sym
        } else {
            Format::Dbc
        }
    }

    /// The format of a file: forced, else by extension, else by content.
    pub fn of_file(forced: Option<Format>, path: &Path, bytes: &[u8]) -> Format {
        forced
            .or_else(|| Format::from_path(path))
            .unwrap_or_else(|| Format::sniff(bytes))
    }
}

impl fmt::Display for Format {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Format::Dbc => "DBC",
            Format::Kcd => "KCD",
            Format::Sym => "SYM",
            Format::Arxml => "ARXML",
            Format::Cdd => "CDD",
        })
    }
}

/// Read a database in `format` (UTF-8, or cp1252 when not valid UTF-8), leniently or strictly.
pub fn load(
    bytes: &[u8],
    format: Format,
    mode: Mode,
) -> Result<(Database, Vec<Diagnostic>), ParseError> {
    load_bus(bytes, format, mode, None)
}

/// [`load`], keeping only the bus named `bus` of a file that describes several (an ARXML
/// system's CAN clusters; a file of one bus must name it). Without `bus`, every bus, each
/// message's in its `BusName` attribute when there are several.
pub fn load_bus(
    bytes: &[u8],
    format: Format,
    mode: Mode,
    bus: Option<&str>,
) -> Result<(Database, Vec<Diagnostic>), ParseError> {
    let (db, diagnostics) = match format {
        Format::Dbc => crate::parser::parse(bytes, mode),
        Format::Kcd => crate::kcd::read(&text_of(bytes), mode),
        Format::Sym => crate::sym::read(&text_of(bytes), mode),
        Format::Arxml => return crate::arxml::read(&text_of(bytes), mode, bus),
        Format::Cdd => crate::cdd::read(&text_of(bytes), mode),
    }?;
    if let Some(wanted) = bus {
        let name = db.attributes.iter().find_map(|(n, v)| match v {
            AttrValue::Str(s) if n == "DBName" => Some(s.as_str()),
            _ => None,
        });
        if let Some(name) = name.filter(|n| *n != wanted) {
            return Err(Report::fatal(
                Position::default(),
                format!("the database is bus {name}, not {wanted}"),
            ));
        }
    }
    Ok((db, diagnostics))
}

/// `bytes` as text: UTF-8 when valid, else cp1252 (what PCAN and Vector tools write).
pub(crate) fn text_of(bytes: &[u8]) -> std::borrow::Cow<'_, str> {
    match std::str::from_utf8(bytes) {
        Ok(t) => std::borrow::Cow::Borrowed(t),
        Err(_) => std::borrow::Cow::Owned(bywire_core::text::cp1252_chars(bytes).collect()),
    }
}

/// Something a target format cannot say, left out of the written file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Omission {
    /// What was left out, naming its object.
    pub what: String,
}

impl fmt::Display for Omission {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.what)
    }
}

/// `db` as text in `format`, with what the format could not say; DBC for a format bywire
/// only reads ([`Format::is_written`]).
pub fn write(db: &Database, format: Format) -> (String, Vec<Omission>) {
    let (db, mut omissions) = without_containers(db);
    let (text, more) = match format {
        Format::Dbc | Format::Arxml | Format::Cdd => (crate::writer::write(&db), Vec::new()),
        Format::Kcd => crate::kcd::write(&db),
        Format::Sym => crate::sym::write(&db),
    };
    omissions.extend(more);
    (text, omissions)
}

/// The database less its container PDUs (no written format has them), and that omission.
fn without_containers(db: &Database) -> (std::borrow::Cow<'_, Database>, Vec<Omission>) {
    if db.containers.is_empty() {
        return (std::borrow::Cow::Borrowed(db), Vec::new());
    }
    let mut out = db.clone();
    let pdus: usize = out.containers.iter().map(|c| c.pdus.len()).sum();
    let what = format!(
        "{} container frames' {pdus} contained PDUs (the frames stay, without signals)",
        out.containers.len()
    );
    out.containers.clear();
    (std::borrow::Cow::Owned(out), vec![Omission { what }])
}

/// `db` reduced to what `format` can say (the database its file reads back as), and what the
/// reduction dropped.
pub fn expressible(db: &Database, format: Format) -> (Database, Vec<Omission>) {
    let (db, mut omissions) = without_containers(db);
    let (out, more) = match format {
        Format::Dbc | Format::Arxml | Format::Cdd => (db.into_owned(), Vec::new()),
        Format::Kcd => crate::kcd::expressible(&db),
        Format::Sym => crate::sym::expressible(&db),
    };
    omissions.extend(more);
    (out, omissions)
}

/// DBC's start bit of a signal whose start KCD and SYM give counted in network order (a
/// big-endian signal's most significant bit with each byte's bits numbered from the top): the
/// inverse of [`Signal::network_start_bit`], which is what their writers write.
pub(crate) fn start_bit_from_network(byte_order: ByteOrder, start: u32) -> u32 {
    match byte_order {
        ByteOrder::LittleEndian => start,
        ByteOrder::BigEndian => 8 * (start / 8) + (7 - start % 8),
    }
}

/// An unsigned, unscaled signal with no range, unit, receiver, comment or value names: what a
/// reader starts from before the file says more.
pub(crate) fn plain_signal(
    name: String,
    (start_bit, length, byte_order): (u32, u32, ByteOrder),
    multiplexing: Multiplexing,
    position: Position,
) -> Signal {
    Signal {
        name,
        start_bit,
        length,
        byte_order,
        value_type: ValueType::Integer { signed: false },
        factor: Num::Int(1),
        offset: Num::Int(0),
        minimum: Num::Int(0),
        maximum: Num::Int(0),
        unit: String::new(),
        receivers: vec![NO_NODE.to_string()],
        multiplexing,
        mux_condition: None,
        comment: None,
        attributes: Vec::new(),
        value_descriptions: Vec::new(),
        position,
    }
}

/// The largest identifier of a frame format.
pub(crate) fn id_limit(extended: bool) -> u32 {
    if extended {
        0x1FFF_FFFF
    } else {
        0x7FF
    }
}

/// The node name DBC uses for "no node".
pub(crate) const NO_NODE: &str = "Vector__XXX";

/// The attributes other formats' facts become, with their DBC definitions.
pub(crate) mod attrs {
    use crate::model::*;

    /// `GenMsgCycleTime`, milliseconds.
    pub const CYCLE_TIME: &str = "GenMsgCycleTime";
    /// `VFrameFormat`, the frame's format.
    pub const FRAME_FORMAT: &str = "VFrameFormat";
    /// `VFrameFormat`'s values, by index.
    pub const FRAME_FORMATS: [&str; 4] = [
        "StandardCAN",
        "ExtendedCAN",
        "StandardCAN_FD",
        "ExtendedCAN_FD",
    ];
    /// `LongName`, a SYM signal's long name (`/ln:`), as canmatrix calls it. Not DBC's
    /// `SystemSignalLongSymbol`: that replaces the signal's name, this one only describes it.
    pub const LONG_NAME: &str = "LongName";
    /// `GenSigStartValue`, a signal's raw value before anything was received.
    pub const START_VALUE: &str = "GenSigStartValue";
    /// `SPN`, a J1939 suspect parameter number.
    pub const SPN: &str = "SPN";

    /// The definition a reader gives each of these when a file uses it.
    pub fn definition(name: &str) -> Option<AttrDef> {
        let int = |scope, max: i128| (scope, AttrType::Int(Num::Int(0), Num::Int(max)));
        let (scope, kind) = match name {
            CYCLE_TIME => int(AttrScope::Message, 3_600_000),
            SPN => int(AttrScope::Signal, 524_287),
            START_VALUE => (
                AttrScope::Signal,
                AttrType::Float(Num::Float(-1.0e300), Num::Float(1.0e300)),
            ),
            LONG_NAME => (AttrScope::Signal, AttrType::Str),
            FRAME_FORMAT => (
                AttrScope::Message,
                AttrType::Enum(FRAME_FORMATS.iter().map(|s| s.to_string()).collect()),
            ),
            _ => return None,
        };
        let default = match &kind {
            AttrType::Str => AttrValue::Str(String::new()),
            AttrType::Float(..) => AttrValue::Number(Num::Float(0.0)),
            _ => AttrValue::Number(Num::Int(0)),
        };
        Some(AttrDef {
            scope,
            name: name.to_string(),
            kind,
            default: Some(default),
        })
    }

    /// Define every attribute of this family that `db` uses, in a fixed order, replacing
    /// whatever definitions it had: the form every reader gives and [`super::expressible`]
    /// reduces to.
    pub fn define_used(db: &mut Database) {
        db.attribute_defs = [CYCLE_TIME, FRAME_FORMAT, LONG_NAME, START_VALUE, SPN]
            .into_iter()
            .filter(|name| used(db, name))
            .filter_map(definition)
            .collect();
    }

    /// Whether the network, a message or a signal of `db` has a value of attribute `name`.
    pub fn used(db: &Database, name: &str) -> bool {
        db.attributes.iter().any(|(n, _)| n == name)
            || db.messages.iter().any(|m| {
                m.attributes.iter().any(|(n, _)| n == name)
                    || m.signals
                        .iter()
                        .any(|s| s.attributes.iter().any(|(n, _)| n == name))
            })
    }
}

/// Line and column of byte offsets in a text, found by binary search over where its lines
/// start (an XML library's own lookup counts lines from the top on every call: a position for
/// each object of a large file made reading quadratic).
pub(crate) struct LineIndex<'t> {
    text: &'t str,
    starts: Vec<usize>,
}

impl<'t> LineIndex<'t> {
    pub(crate) fn new(text: &'t str) -> Self {
        let starts = std::iter::once(0)
            .chain(text.match_indices('\n').map(|(i, _)| i + 1))
            .collect();
        LineIndex { text, starts }
    }

    /// The 1-based line and column (in characters) of byte `offset`.
    pub(crate) fn position(&self, offset: usize) -> Position {
        let line = self.starts.partition_point(|&s| s <= offset).max(1);
        let start = self.starts.get(line - 1).copied().unwrap_or(0);
        let column = self
            .text
            .get(start..offset.min(self.text.len()))
            .map_or(0, |t| t.chars().count());
        Position {
            line: u32::try_from(line).unwrap_or(u32::MAX),
            column: u32::try_from(column + 1).unwrap_or(u32::MAX),
        }
    }
}

/// Diagnostics as a reader collects them: each with its position; in strict mode the first
/// one ends the read.
pub(crate) struct Report {
    mode: Mode,
    pub(crate) items: Vec<Diagnostic>,
}

impl Report {
    pub(crate) fn new(mode: Mode) -> Report {
        Report {
            mode,
            items: Vec::new(),
        }
    }

    /// Record a problem; in strict mode, stop the read with it.
    pub(crate) fn add(
        &mut self,
        severity: Severity,
        at: Position,
        message: impl Into<String>,
        resolution: &str,
    ) -> Result<(), ParseError> {
        let d = Diagnostic {
            line: at.line,
            column: at.column,
            severity,
            message: message.into(),
            resolution: resolution.into(),
        };
        if self.mode == Mode::Strict {
            return Err(ParseError(d));
        }
        self.items.push(d);
        Ok(())
    }

    /// A problem that stops the read whatever the mode.
    pub(crate) fn fatal(at: Position, message: impl Into<String>) -> ParseError {
        ParseError(Diagnostic {
            line: at.line,
            column: at.column,
            severity: Severity::Error,
            message: message.into(),
            resolution: "nothing loaded".into(),
        })
    }

    /// The layout checks every format shares (signals past the end, overlaps, names twice),
    /// then the diagnostics.
    pub(crate) fn finish(
        mut self,
        db: Database,
    ) -> Result<(Database, Vec<Diagnostic>), ParseError> {
        for d in crate::parser::layout_diagnostics(&db) {
            if self.mode == Mode::Strict {
                return Err(ParseError(d));
            }
            self.items.push(d);
        }
        Ok((db, self.items))
    }
}

/// Omissions gathered while reducing a database, each kind of thing named once with a count.
#[derive(Default)]
pub(crate) struct Omissions(Vec<Omission>);

impl Omissions {
    pub(crate) fn add(&mut self, what: impl Into<String>) {
        self.0.push(Omission { what: what.into() });
    }

    /// Name the attributes dropped from `count` objects of a kind, once.
    pub(crate) fn attributes<'a>(
        &mut self,
        kind: &str,
        names: impl Iterator<Item = &'a str>,
        count: usize,
    ) {
        let mut list: Vec<&str> = names.collect();
        list.sort_unstable();
        list.dedup();
        if list.is_empty() {
            return;
        }
        self.add(if count == 0 {
            format!("{kind}s ({})", list.join(", "))
        } else {
            format!("{kind} attributes ({}) on {count} {kind}s", list.join(", "))
        });
    }

    pub(crate) fn into_vec(self) -> Vec<Omission> {
        self.0
    }
}

/// The message's cycle time in whole milliseconds, the file's default counted.
pub(crate) fn cycle_time_ms(db: &Database, m: &Message) -> Option<u64> {
    let ms: f64 = db
        .message_attribute_text(m, attrs::CYCLE_TIME)?
        .parse()
        .ok()?;
    (ms.is_finite() && ms >= 1.0 && ms.fract() == 0.0 && ms < 3_600_001.0).then(|| {
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let whole = ms as u64;
        whole
    })
}

/// Only the attributes of the family in [`attrs`] a format keeps; the others named once.
pub(crate) fn keep_attributes(
    db: &Database,
    kept: &[&str],
    omissions: &mut Omissions,
    keep_message: impl Fn(&Database, &Message) -> Vec<(String, AttrValue)>,
) -> Database {
    let mut out = db.clone();
    let signals = || db.messages.iter().flat_map(|m| &m.signals);
    let dropped = |list: &[(String, AttrValue)]| {
        list.iter()
            .filter(|(n, _)| !kept.contains(&n.as_str()))
            .count()
            > 0
    };
    omissions.attributes(
        "network",
        db.attributes.iter().map(|(n, _)| n.as_str()),
        usize::from(!db.attributes.is_empty()),
    );
    omissions.attributes(
        "node",
        db.nodes
            .iter()
            .flat_map(|n| &n.attributes)
            .map(|(n, _)| n.as_str()),
        db.nodes.iter().filter(|n| !n.attributes.is_empty()).count(),
    );
    omissions.attributes(
        "message",
        db.messages
            .iter()
            .flat_map(|m| &m.attributes)
            .map(|(n, _)| n.as_str())
            .filter(|n| !kept.contains(n)),
        db.messages
            .iter()
            .filter(|m| dropped(&m.attributes))
            .count(),
    );
    omissions.attributes(
        "signal",
        signals()
            .flat_map(|s| &s.attributes)
            .map(|(n, _)| n.as_str())
            .filter(|n| !kept.contains(n)),
        signals().filter(|s| dropped(&s.attributes)).count(),
    );
    let valued = |name: &str| {
        let has = |list: &[(String, AttrValue)]| list.iter().any(|(n, _)| n == name);
        has(&db.attributes)
            || db.nodes.iter().any(|n| has(&n.attributes))
            || db.messages.iter().any(|m| has(&m.attributes))
            || signals().any(|s| has(&s.attributes))
    };
    omissions.attributes(
        "attribute definition",
        db.attribute_defs
            .iter()
            .map(|d| d.name.as_str())
            .filter(|n| !kept.contains(n) && !valued(n)),
        0,
    );
    out.attributes.clear();
    for n in &mut out.nodes {
        n.attributes.clear();
    }
    for (m, original) in out.messages.iter_mut().zip(&db.messages) {
        m.attributes = keep_message(db, original);
        for s in &mut m.signals {
            s.attributes.retain(|(n, _)| kept.contains(&n.as_str()));
        }
    }
    attrs::define_used(&mut out);
    out
}

/// Drop what none of the non-DBC formats say: value tables, environment variables, signal
/// groups, statements kept verbatim, bit timing and node comments.
pub(crate) fn drop_dbc_only(db: &mut Database, omissions: &mut Omissions) {
    if !db.value_tables.is_empty() {
        omissions.add(format!("{} value tables", db.value_tables.len()));
    }
    if !db.env_vars.is_empty() {
        omissions.add(format!("{} environment variables", db.env_vars.len()));
    }
    if !db.signal_groups.is_empty() {
        omissions.add(format!("{} signal groups", db.signal_groups.len()));
    }
    if !db.unknown.is_empty() {
        omissions.add(format!(
            "{} statements kept verbatim from the DBC",
            db.unknown.len()
        ));
    }
    if !db.bit_timing.trim().is_empty() {
        omissions.add("the bit timing (BS_)");
    }
    let commented = db.nodes.iter().filter(|n| n.comment.is_some()).count();
    if commented > 0 {
        omissions.add(format!("comments on {commented} nodes"));
    }
    let before = db.messages.len();
    db.messages
        .retain(|m| m.name != crate::INDEPENDENT_SIGNALS && m.id <= id_limit(m.extended));
    if db.messages.len() < before {
        omissions.add(format!(
            "{} messages without a valid identifier ({} and the like)",
            before - db.messages.len(),
            crate::INDEPENDENT_SIGNALS
        ));
    }
    db.value_tables.clear();
    db.env_vars.clear();
    db.signal_groups.clear();
    db.unknown.clear();
    db.bit_timing.clear();
    db.new_symbols.clear();
    for n in &mut db.nodes {
        n.comment = None;
    }
    // An empty comment and none are the same thing in the other formats.
    let blank = |c: &mut Option<String>| {
        if c.as_deref().is_some_and(|t| t.trim().is_empty()) {
            *c = None;
        }
    };
    blank(&mut db.comment);
    for m in &mut db.messages {
        blank(&mut m.comment);
        for s in &mut m.signals {
            blank(&mut s.comment);
        }
    }
}

/// Extended multiplexing (`SG_MUL_VAL_`) and multiplexors inside a multiplexed group reduced to
/// simple multiplexing, each reduction named.
pub(crate) fn simple_multiplexing(db: &mut Database, omissions: &mut Omissions) {
    for m in &mut db.messages {
        for s in &mut m.signals {
            if let Some(c) = s.mux_condition.take() {
                let simple =
                    matches!(s.multiplexing, Multiplexing::Multiplexed(v) if c.ranges == [(v, v)]);
                if !simple {
                    omissions.add(format!(
                        "extended multiplexing of signal {} in message {}",
                        s.name, m.name
                    ));
                }
            }
            if let Multiplexing::MultiplexedMultiplexor(v) = s.multiplexing {
                omissions.add(format!(
                    "signal {} in message {} as a multiplexor (it stays multiplexed by {v})",
                    s.name, m.name
                ));
                s.multiplexing = Multiplexing::Multiplexed(v);
            }
        }
    }
}

/// A message's signals in the order a multiplexing format writes them: each multiplexor
/// followed by its groups, in the order their values first appear, the others where they were.
pub(crate) fn grouped_signal_order(signals: &[Signal]) -> Vec<Signal> {
    let mut out: Vec<Signal> = Vec::with_capacity(signals.len());
    let muxed = |s: &Signal| matches!(s.multiplexing, Multiplexing::Multiplexed(_));
    let has_multiplexor = signals
        .iter()
        .any(|s| s.multiplexing == Multiplexing::Multiplexor);
    for s in signals {
        if muxed(s) && has_multiplexor {
            continue;
        }
        out.push(s.clone());
        if s.multiplexing == Multiplexing::Multiplexor {
            let mut values: Vec<u64> = Vec::new();
            for o in signals {
                if let Multiplexing::Multiplexed(v) = o.multiplexing {
                    if !values.contains(&v) {
                        values.push(v);
                    }
                }
            }
            for v in values {
                out.extend(
                    signals
                        .iter()
                        .filter(|o| o.multiplexing == Multiplexing::Multiplexed(v))
                        .cloned(),
                );
            }
        }
    }
    out
}

/// Nodes that transmitters and receivers name but the node list lacks, appended to it (a
/// format that refers to nodes by number must declare them).
pub(crate) fn declare_referenced_nodes(db: &mut Database) {
    let mut missing: Vec<String> = Vec::new();
    for m in &db.messages {
        let names = std::iter::once(&m.transmitter)
            .chain(&m.senders)
            .chain(m.signals.iter().flat_map(|s| &s.receivers));
        for name in names {
            if name != NO_NODE
                && !db.nodes.iter().any(|n| &n.name == name)
                && !missing.contains(name)
            {
                missing.push(name.clone());
            }
        }
    }
    db.nodes.extend(missing.into_iter().map(|name| Node {
        name,
        comment: None,
        attributes: Vec::new(),
    }));
}

/// Escape text for an XML attribute or element.
pub(crate) fn xml_escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            '\n' => out.push_str("&#10;"),
            '\r' => out.push_str("&#13;"),
            '\t' => out.push_str("&#9;"),
            c => out.push(c),
        }
    }
    out
}

/// Set a signal's range from the bounds a file gave: both, none (0 and 0, DBC's "no range"), or
/// one, the other then as far as the signal reaches (a missing bound read as 0 would put every
/// value on that side out of range).
pub(crate) fn set_range(signal: &mut Signal, minimum: Option<Num>, maximum: Option<Num>) {
    let (low, high) = signal.reachable_range().unwrap_or(match signal.value_type {
        ValueType::Float32 => (f64::from(f32::MIN), f64::from(f32::MAX)),
        _ => (f64::MIN, f64::MAX),
    });
    (signal.minimum, signal.maximum) = match (minimum, maximum) {
        (Some(min), Some(max)) => (min, max),
        (None, None) => (Num::Int(0), Num::Int(0)),
        (Some(min), None) => (min, Num::Float(high)),
        (None, Some(max)) => (Num::Float(low), max),
    };
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn line_index_positions_are_the_xml_parsers() {
        let text = "<a>\n  <b x=\"é\"/>\r\n\n<c>ü<d/></c>\n</a>";
        let doc = roxmltree::Document::parse(text).unwrap();
        let lines = LineIndex::new(text);
        for n in doc.descendants() {
            let theirs = doc.text_pos_at(n.range().start);
            let ours = lines.position(n.range().start);
            assert_eq!((ours.line, ours.column), (theirs.row, theirs.col), "{n:?}");
        }
    }

    #[test]
    fn formats_are_named_by_extension_and_recognised_by_content() {
        assert_eq!(Format::from_path(Path::new("a/b.KCD")), Some(Format::Kcd));
        assert_eq!(Format::from_path(Path::new("x.txt")), None);
        assert_eq!(
            Format::sniff(b"<?xml version=\"1.0\"?>\n<NetworkDefinition xmlns=\"x\"/>"),
            Format::Kcd
        );
        assert_eq!(
            Format::sniff(b"FormatVersion=6.0 // Do not edit\n"),
            Format::Sym
        );
        assert_eq!(Format::sniff(b"VERSION \"\"\n"), Format::Dbc);
        assert_eq!(
            Format::of_file(Some(Format::Dbc), Path::new("x.kcd"), b""),
            Format::Dbc
        );
    }
}
