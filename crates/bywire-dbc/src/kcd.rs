//! KCD, the XML network definition of Kayak (and SavvyCAN), as cantools reads it.
//!
//! A `NetworkDefinition` holds a `Document` (version, and the network's comment as its text),
//! `Node`s by number and `Bus`es of `Message`s. A message's `Signal`s and `Multiplex`ors (each
//! with `MuxGroup`s of signals) give an `offset` counted as cantools counts it: a little-endian
//! signal's least significant bit; a big-endian one's most significant bit with the bits of
//! each byte numbered from the top, which is DBC's start bit with the byte's bits reversed.

use roxmltree::{Document, Node as XmlNode};

use crate::format::{
    self, attrs, cycle_time_ms, declare_referenced_nodes, drop_dbc_only, grouped_signal_order,
    keep_attributes, plain_signal, simple_multiplexing, start_bit_from_network, xml_escape,
    LineIndex, Omission, Omissions, Report, NO_NODE,
};
use crate::model::*;
use crate::parser::{parse_num, Diagnostic, Mode, ParseError, Severity};

const NAMESPACE: &str = "http://kayak.2codeornot2code.org/1.0";

/// Elements a KCD file may hold before it is refused (a 10 MB file has about a million).
const MAX_NODES: u32 = 20_000_000;

/// Read KCD text.
pub(crate) fn read(text: &str, mode: Mode) -> Result<(Database, Vec<Diagnostic>), ParseError> {
    let doc = crate::xml::parse(text, false, MAX_NODES)?;
    let lines = LineIndex::new(text);
    let mut reader = Reader {
        doc: &doc,
        lines: &lines,
        report: Report::new(mode),
        node_ids: Vec::new(),
    };
    let db = reader.network()?;
    reader.report.finish(db)
}

struct Reader<'a, 'input> {
    doc: &'a Document<'input>,
    lines: &'a LineIndex<'input>,
    report: Report,
    node_ids: Vec<(String, String)>,
}

impl<'input> Reader<'_, 'input> {
    fn at(&self, n: XmlNode<'_, 'input>) -> Position {
        self.lines.position(n.range().start)
    }

    fn problem(
        &mut self,
        n: XmlNode<'_, 'input>,
        message: impl Into<String>,
        resolution: &str,
    ) -> Result<(), ParseError> {
        let at = self.at(n);
        self.report.add(Severity::Error, at, message, resolution)
    }

    fn network(&mut self) -> Result<Database, ParseError> {
        let root = self.doc.root_element();
        if root.tag_name().name() != "NetworkDefinition" {
            return Err(Report::fatal(
                self.at(root),
                format!(
                    "the root element is {}, not a KCD NetworkDefinition",
                    root.tag_name().name()
                ),
            ));
        }
        if root.tag_name().namespace() != Some(NAMESPACE) {
            let at = self.at(root);
            self.report.add(
                Severity::Warning,
                at,
                format!("the NetworkDefinition is not in KCD's namespace {NAMESPACE}"),
                "read as KCD",
            )?;
        }
        let mut db = Database::default();
        for child in root.children().filter(XmlNode::is_element) {
            match child.tag_name().name() {
                "Document" => {
                    db.version = child.attribute("version").unwrap_or_default().to_string();
                    db.comment = text(child);
                }
                "Node" => {
                    let (Some(id), Some(name)) = (child.attribute("id"), child.attribute("name"))
                    else {
                        self.problem(child, "a Node without id or name", "node skipped")?;
                        continue;
                    };
                    self.node_ids.push((id.to_string(), name.to_string()));
                    db.nodes.push(Node {
                        name: name.to_string(),
                        comment: None,
                        attributes: Vec::new(),
                    });
                }
                "Bus" => {
                    for m in child.children().filter(|m| is(m, "Message")) {
                        if let Some(message) = self.message(m)? {
                            db.messages.push(message);
                        }
                    }
                }
                _ => {}
            }
        }
        attrs::define_used(&mut db);
        Ok(db)
    }

    fn node_refs(&mut self, parent: XmlNode<'_, 'input>) -> Result<Vec<String>, ParseError> {
        let mut names = Vec::new();
        for r in parent.children().filter(|r| is(r, "NodeRef")) {
            let id = r.attribute("id").unwrap_or_default();
            match self.node_ids.iter().find(|(i, _)| i == id) {
                Some((_, name)) => names.push(name.clone()),
                None => self.problem(
                    r,
                    format!("NodeRef {id} names no Node"),
                    "reference skipped",
                )?,
            }
        }
        Ok(names)
    }

    fn message(&mut self, m: XmlNode<'_, 'input>) -> Result<Option<Message>, ParseError> {
        let name = m.attribute("name").unwrap_or_default().to_string();
        let Some(id) = m.attribute("id").and_then(parse_id) else {
            self.problem(
                m,
                format!("message {name} has no identifier KCD reads (0x… or decimal)"),
                "message skipped",
            )?;
            return Ok(None);
        };
        let extended = m.attribute("format") == Some("extended");
        let limit = if extended { 0x1FFF_FFFF } else { 0x7FF };
        if id > limit {
            self.problem(
                m,
                format!("message {name}'s identifier {id:#x} is too large for its format"),
                "message skipped",
            )?;
            return Ok(None);
        }
        let mut signals = Vec::new();
        let mut producers = Vec::new();
        let mut comment = None;
        for child in m.children().filter(XmlNode::is_element) {
            match child.tag_name().name() {
                "Notes" => comment = text(child),
                "Producer" => producers = self.node_refs(child)?,
                "Signal" => signals.extend(self.signal(child, Multiplexing::None)?),
                "Multiplex" => {
                    let Some(mux) = self.signal(child, Multiplexing::Multiplexor)? else {
                        continue;
                    };
                    signals.push(mux);
                    for group in child.children().filter(|g| is(g, "MuxGroup")) {
                        let Some(count) = group.attribute("count").and_then(|c| c.parse().ok())
                        else {
                            self.problem(group, "a MuxGroup without a count", "group skipped")?;
                            continue;
                        };
                        for s in group.children().filter(|s| is(s, "Signal")) {
                            signals.extend(self.signal(s, Multiplexing::Multiplexed(count))?);
                        }
                    }
                }
                _ => {}
            }
        }
        name_switches(&mut signals);
        let size = match m.attribute("length") {
            None | Some("auto") => signals
                .iter()
                .map(|s: &Signal| (s.network_start_bit() + s.length).div_ceil(8))
                .max()
                .unwrap_or(0),
            Some(n) => match n.parse::<u32>() {
                Ok(n) if n <= 64 => n,
                _ => {
                    self.problem(
                        m,
                        format!("message {name}'s length {n} is not 0 to 64 bytes"),
                        "message skipped",
                    )?;
                    return Ok(None);
                }
            },
        };
        let mut attributes = Vec::new();
        if let Some(interval) = m.attribute("interval") {
            match interval.parse::<u32>() {
                Ok(ms) if ms > 0 => attributes.push((
                    attrs::CYCLE_TIME.to_string(),
                    AttrValue::Number(Num::Int(i128::from(ms))),
                )),
                Ok(_) => {}
                Err(_) => self.problem(
                    m,
                    format!("message {name}'s interval {interval} is not a whole number of ms"),
                    "no cycle time",
                )?,
            }
        }
        let mut producers = producers.into_iter();
        Ok(Some(Message {
            id,
            extended,
            name,
            size,
            transmitter: producers.next().unwrap_or_else(|| NO_NODE.to_string()),
            senders: producers.collect(),
            signals,
            comment,
            attributes,
            position: self.at(m),
        }))
    }

    fn signal(
        &mut self,
        s: XmlNode<'_, 'input>,
        multiplexing: Multiplexing,
    ) -> Result<Option<Signal>, ParseError> {
        let name = s.attribute("name").unwrap_or_default().to_string();
        let number = |key: &str, default: u32| s.attribute(key).map_or(Ok(default), str::parse);
        let (Ok(offset), Ok(length)) = (number("offset", 0), number("length", 1)) else {
            self.problem(
                s,
                format!("signal {name}'s offset or length is not a number"),
                "signal skipped",
            )?;
            return Ok(None);
        };
        if s.attribute("offset").is_none() || !(1..=64).contains(&length) || offset >= 512 {
            self.problem(
                s,
                format!("signal {name} needs an offset below 512 and a length of 1 to 64 bits"),
                "signal skipped",
            )?;
            return Ok(None);
        }
        let byte_order = match s.attribute("endianess") {
            Some("big") => ByteOrder::BigEndian,
            None | Some("little") => ByteOrder::LittleEndian,
            Some(other) => {
                self.problem(
                    s,
                    format!("signal {name}'s endianess {other} is neither little nor big"),
                    "read as little",
                )?;
                ByteOrder::LittleEndian
            }
        };
        let start_bit = start_bit_from_network(byte_order, offset);
        let mut signal = plain_signal(
            name,
            (start_bit, length, byte_order),
            multiplexing,
            self.at(s),
        );
        for child in s.children().filter(XmlNode::is_element) {
            match child.tag_name().name() {
                "Notes" => signal.comment = text(child),
                "Consumer" => signal.receivers = self.node_refs(child)?,
                "Value" => self.value(child, &mut signal)?,
                "LabelSet" => {
                    for label in child.children().filter(XmlNode::is_element) {
                        if is(&label, "Label") {
                            let value = label.attribute("value").and_then(|v| v.parse().ok());
                            match (value, label.attribute("name")) {
                                (Some(v), Some(n)) => {
                                    signal.value_descriptions.push((v, n.to_string()));
                                }
                                _ => self.problem(
                                    label,
                                    "a Label without an integer value and a name",
                                    "label skipped",
                                )?,
                            }
                        } else if is(&label, "LabelGroup") {
                            self.problem(
                                label,
                                format!(
                                    "signal {}'s LabelGroup (a range of values under one name)",
                                    signal.name
                                ),
                                "group skipped, as cantools does",
                            )?;
                        }
                    }
                }
                _ => {}
            }
        }
        if signal.receivers.is_empty() {
            signal.receivers.push(NO_NODE.to_string());
        }
        Ok(Some(signal))
    }

    fn value(&mut self, v: XmlNode<'_, 'input>, signal: &mut Signal) -> Result<(), ParseError> {
        let (mut minimum, mut maximum) = (None, None);
        for attribute in v.attributes() {
            let field = match attribute.name() {
                "slope" => &mut signal.factor,
                "intercept" => &mut signal.offset,
                "min" | "max" => {
                    let bound = parse_num(attribute.value().trim());
                    if bound.is_none() {
                        self.problem(
                            v,
                            format!(
                                "signal {}'s {} {} is not a number",
                                signal.name,
                                attribute.name(),
                                attribute.value()
                            ),
                            "no bound",
                        )?;
                    }
                    *(if attribute.name() == "min" {
                        &mut minimum
                    } else {
                        &mut maximum
                    }) = bound;
                    continue;
                }
                "unit" => {
                    signal.unit = attribute.value().to_string();
                    continue;
                }
                "type" => {
                    signal.value_type = match attribute.value() {
                        "signed" => ValueType::Integer { signed: true },
                        "single" => ValueType::Float32,
                        "double" => ValueType::Float64,
                        "unsigned" => ValueType::Integer { signed: false },
                        other => {
                            self.problem(v, format!("signal {}'s type {other} is not unsigned, signed, single or double", signal.name), "read as unsigned")?;
                            ValueType::Integer { signed: false }
                        }
                    };
                    continue;
                }
                _ => continue,
            };
            match parse_num(attribute.value().trim()) {
                Some(n) => *field = n,
                None => self.problem(
                    v,
                    format!(
                        "signal {}'s {} {} is not a number",
                        signal.name,
                        attribute.name(),
                        attribute.value()
                    ),
                    "default kept",
                )?,
            }
        }
        format::set_range(signal, minimum, maximum);
        let float_length = match signal.value_type {
            ValueType::Float32 => Some(32),
            ValueType::Float64 => Some(64),
            ValueType::Integer { .. } => None,
        };
        if let Some(bits) = float_length.filter(|&b| b != signal.length) {
            self.problem(
                v,
                format!(
                    "signal {} is a {bits}-bit float but {} bits long",
                    signal.name, signal.length
                ),
                "read as an integer",
            )?;
            signal.value_type = ValueType::Integer { signed: false };
        }
        Ok(())
    }
}

/// Of several multiplexors in a message, each multiplexed signal names the one whose group it
/// stands in (as extended multiplexing does); with one, simple multiplexing says it all.
fn name_switches(signals: &mut [Signal]) {
    let multiplexors = signals
        .iter()
        .filter(|s| s.multiplexing == Multiplexing::Multiplexor)
        .count();
    if multiplexors < 2 {
        return;
    }
    let mut switch = String::new();
    for s in signals {
        match s.multiplexing {
            Multiplexing::Multiplexor => switch.clone_from(&s.name),
            Multiplexing::Multiplexed(v) => {
                s.mux_condition = Some(MuxCondition {
                    switch: switch.clone(),
                    ranges: vec![(v, v)],
                });
            }
            _ => {}
        }
    }
}

/// Whether `n` is an element of this local name (in any namespace: files in the wild differ).
fn is(n: &XmlNode<'_, '_>, local: &str) -> bool {
    n.is_element() && n.tag_name().name() == local
}

/// An element's text, when it has any besides white space.
fn text(n: XmlNode<'_, '_>) -> Option<String> {
    let t = n.text()?;
    (!t.trim().is_empty()).then(|| t.to_string())
}

/// `0x…` in hexadecimal, else decimal (as Python's `int(value, 0)` reads KCD identifiers).
fn parse_id(text: &str) -> Option<u32> {
    let t = text.trim();
    match t.strip_prefix("0x").or_else(|| t.strip_prefix("0X")) {
        Some(hex) => u32::from_str_radix(hex, 16).ok(),
        None => t.parse().ok(),
    }
}

/// `db` reduced to what KCD says.
pub(crate) fn expressible(db: &Database) -> (Database, Vec<Omission>) {
    let mut omissions = Omissions::default();
    let mut out = keep_attributes(db, &[attrs::CYCLE_TIME], &mut omissions, |db, m| {
        cycle_time_ms(db, m)
            .map(|ms| {
                vec![(
                    attrs::CYCLE_TIME.to_string(),
                    AttrValue::Number(Num::Int(i128::from(ms))),
                )]
            })
            .unwrap_or_default()
    });
    drop_dbc_only(&mut out, &mut omissions);
    simple_multiplexing(&mut out, &mut omissions);
    let fd: Vec<&str> = db
        .messages
        .iter()
        .filter(|m| db.fd_format(m).0)
        .map(|m| m.name.as_str())
        .collect();
    if !fd.is_empty() {
        omissions.add(format!(
            "the CAN FD format of messages {} (KCD has no CAN FD)",
            fd.join(", ")
        ));
    }
    let oversized: Vec<&str> = out
        .messages
        .iter()
        .filter(|m| m.signals.iter().any(|s| s.start_bit >= 512))
        .map(|m| m.name.as_str())
        .collect();
    if !oversized.is_empty() {
        omissions.add(format!(
            "signals starting past bit 511 in messages {}",
            oversized.join(", ")
        ));
    }
    for m in &mut out.messages {
        m.signals.retain(|s| s.start_bit < 512);
        m.signals = grouped_signal_order(&m.signals);
        name_switches(&mut m.signals);
        for s in &mut m.signals {
            s.receivers.retain(|r| r != NO_NODE);
            if s.receivers.is_empty() {
                s.receivers.push(NO_NODE.to_string());
            }
        }
    }
    declare_referenced_nodes(&mut out);
    (out, omissions.into_vec())
}

/// `db` as KCD text, with what KCD could not say.
pub(crate) fn write(db: &Database) -> (String, Vec<Omission>) {
    let (db, omissions) = expressible(db);
    let mut o = String::new();
    o.push_str("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n");
    o.push_str(&format!(
        "<NetworkDefinition xmlns=\"{NAMESPACE}\" xmlns:xsi=\"http://www.w3.org/2001/XMLSchema-instance\" xsi:noNamespaceSchemaLocation=\"Definition.xsd\">\n"
    ));
    o.push_str(&format!(
        "  <Document version=\"{}\">{}</Document>\n",
        xml_escape(&db.version),
        xml_escape(db.comment.as_deref().unwrap_or_default())
    ));
    let node_id = |name: &str| db.nodes.iter().position(|n| n.name == name).map(|i| i + 1);
    for (i, n) in db.nodes.iter().enumerate() {
        o.push_str(&format!(
            "  <Node id=\"{}\" name=\"{}\"/>\n",
            i + 1,
            xml_escape(&n.name)
        ));
    }
    o.push_str("  <Bus name=\"Bus\">\n");
    let node_refs = |o: &mut String, indent: &str, element: &str, names: &[&String]| {
        let ids: Vec<usize> = names.iter().filter_map(|n| node_id(n)).collect();
        if ids.is_empty() {
            return;
        }
        o.push_str(&format!("{indent}<{element}>\n"));
        for id in ids {
            o.push_str(&format!("{indent}  <NodeRef id=\"{id}\"/>\n"));
        }
        o.push_str(&format!("{indent}</{element}>\n"));
    };
    for m in &db.messages {
        o.push_str(&format!(
            "    <Message id=\"0x{:03X}\" name=\"{}\" length=\"{}\"",
            m.id,
            xml_escape(&m.name),
            m.size
        ));
        if let Some(ms) = cycle_time_ms(&db, m) {
            o.push_str(&format!(" interval=\"{ms}\""));
        }
        if m.extended {
            o.push_str(" format=\"extended\"");
        }
        o.push_str(">\n");
        if let Some(c) = &m.comment {
            o.push_str(&format!("      <Notes>{}</Notes>\n", xml_escape(c)));
        }
        let producers: Vec<&String> = std::iter::once(&m.transmitter).chain(&m.senders).collect();
        node_refs(&mut o, "      ", "Producer", &producers);
        let mut open_group: Option<u64> = None;
        let mut in_multiplex = false;
        for s in &m.signals {
            match s.multiplexing {
                Multiplexing::Multiplexed(v) if in_multiplex => {
                    if open_group != Some(v) {
                        if open_group.is_some() {
                            o.push_str("        </MuxGroup>\n");
                        }
                        o.push_str(&format!("        <MuxGroup count=\"{v}\">\n"));
                        open_group = Some(v);
                    }
                    signal(&mut o, "          ", "Signal", s, &node_refs);
                    continue;
                }
                _ => {}
            }
            close_multiplex(&mut o, &mut in_multiplex, &mut open_group);
            if s.multiplexing == Multiplexing::Multiplexor {
                signal_open(&mut o, "      ", "Multiplex", s, &node_refs);
                in_multiplex = true;
            } else {
                signal(&mut o, "      ", "Signal", s, &node_refs);
            }
        }
        close_multiplex(&mut o, &mut in_multiplex, &mut open_group);
        o.push_str("    </Message>\n");
    }
    o.push_str("  </Bus>\n</NetworkDefinition>\n");
    (o, omissions)
}

fn close_multiplex(o: &mut String, in_multiplex: &mut bool, open_group: &mut Option<u64>) {
    if open_group.take().is_some() {
        o.push_str("        </MuxGroup>\n");
    }
    if std::mem::take(in_multiplex) {
        o.push_str("      </Multiplex>\n");
    }
}

type NodeRefs<'a> = dyn Fn(&mut String, &str, &str, &[&String]) + 'a;

fn signal(o: &mut String, indent: &str, element: &str, s: &Signal, node_refs: &NodeRefs<'_>) {
    signal_open(o, indent, element, s, node_refs);
    o.push_str(&format!("{indent}</{element}>\n"));
}

/// A signal's element and its contents, left open (a `Multiplex` goes on with its groups).
fn signal_open(o: &mut String, indent: &str, element: &str, s: &Signal, node_refs: &NodeRefs<'_>) {
    let offset = s.network_start_bit();
    o.push_str(&format!(
        "{indent}<{element} name=\"{}\" offset=\"{offset}\" length=\"{}\"",
        xml_escape(&s.name),
        s.length
    ));
    if s.byte_order == ByteOrder::BigEndian {
        o.push_str(" endianess=\"big\"");
    }
    o.push_str(">\n");
    let inner = format!("{indent}  ");
    if let Some(c) = &s.comment {
        o.push_str(&format!("{inner}<Notes>{}</Notes>\n", xml_escape(c)));
    }
    let receivers: Vec<&String> = s.receivers.iter().collect();
    node_refs(o, &inner, "Consumer", &receivers);
    let kind = match s.value_type {
        ValueType::Integer { signed: false } => "unsigned",
        ValueType::Integer { signed: true } => "signed",
        ValueType::Float32 => "single",
        ValueType::Float64 => "double",
    };
    o.push_str(&format!(
        "{inner}<Value type=\"{kind}\" slope=\"{}\" intercept=\"{}\" min=\"{}\" max=\"{}\" unit=\"{}\"/>\n",
        s.factor,
        s.offset,
        s.minimum,
        s.maximum,
        xml_escape(&s.unit)
    ));
    if !s.value_descriptions.is_empty() {
        o.push_str(&format!("{inner}<LabelSet>\n"));
        for (value, name) in &s.value_descriptions {
            o.push_str(&format!(
                "{inner}  <Label value=\"{value}\" name=\"{}\"/>\n",
                xml_escape(name)
            ));
        }
        o.push_str(&format!("{inner}</LabelSet>\n"));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const KCD: &str = r#"<NetworkDefinition xmlns="http://kayak.2codeornot2code.org/1.0">
  <Document version="1.2">A network</Document>
  <Node id="1" name="ECU"/>
  <Node id="2" name="Display"/>
  <Bus name="Main">
    <Message id="0x123" name="Status" length="auto" interval="50">
      <Notes>Status frame</Notes>
      <Producer><NodeRef id="1"/></Producer>
      <Multiplex name="Page" offset="0" length="4">
        <MuxGroup count="1">
          <Signal name="Speed" offset="8" length="16" endianess="big">
            <Consumer><NodeRef id="2"/></Consumer>
            <Value type="signed" slope="0.1" intercept="-5" min="-100" max="100" unit="km/h"/>
          </Signal>
        </MuxGroup>
      </Multiplex>
      <Signal name="Mode" offset="4" length="2">
        <LabelSet><Label value="0" name="Off"/><Label value="1" name="On"/></LabelSet>
      </Signal>
    </Message>
  </Bus>
</NetworkDefinition>"#;

    #[test]
    fn reads_messages_signals_multiplexing_and_labels() {
        let (db, diagnostics) = read(KCD, Mode::Strict).unwrap();
        assert!(diagnostics.is_empty(), "{diagnostics:?}");
        assert_eq!(db.version, "1.2");
        assert_eq!(db.comment.as_deref(), Some("A network"));
        let m = &db.messages[0];
        assert_eq!((m.id, m.size, m.transmitter.as_str()), (0x123, 3, "ECU"));
        assert_eq!(db.cycle_time(m), Some(std::time::Duration::from_millis(50)));
        let speed = m.signal("Speed").unwrap();
        assert_eq!(speed.start_bit, 15);
        assert_eq!(speed.multiplexing, Multiplexing::Multiplexed(1));
        assert_eq!(speed.factor, Num::Float(0.1));
        assert_eq!(speed.receivers, ["Display"]);
        assert_eq!(
            m.signal("Page").unwrap().multiplexing,
            Multiplexing::Multiplexor
        );
        assert_eq!(m.signal("Mode").unwrap().value_descriptions.len(), 2);
    }

    #[test]
    fn written_kcd_reads_back_as_what_kcd_can_say() {
        let (db, _) = read(KCD, Mode::Strict).unwrap();
        let (text, omissions) = write(&db);
        assert!(omissions.is_empty(), "{omissions:?}");
        let (back, _) = read(&text, Mode::Strict).unwrap();
        assert_eq!(back, db);
    }

    #[test]
    fn bad_files_get_a_positioned_error() {
        let e = read("<NetworkDefinition><Bus", Mode::Lenient).unwrap_err();
        assert_eq!(e.0.line, 1);
        let e = read("<Other/>", Mode::Lenient).unwrap_err();
        assert!(e.0.message.contains("Other"), "{e}");
        let bad = KCD.replace("offset=\"4\"", "offset=\"x\"");
        let (db, diagnostics) = read(&bad, Mode::Lenient).unwrap();
        assert_eq!(diagnostics.len(), 1, "{diagnostics:?}");
        assert_eq!(diagnostics[0].line, 17);
        assert!(db.messages[0].signal("Mode").is_none());
        assert!(read(&bad, Mode::Strict).is_err());
    }
}
