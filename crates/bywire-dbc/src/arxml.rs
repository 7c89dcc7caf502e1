//! AUTOSAR system descriptions (ARXML, AUTOSAR 3.x and 4.x): the CAN clusters' frames, read
//! into the one model the way cantools reads them, with what cantools leaves aside.
//!
//! Each CAN frame triggering of a cluster is a message: the frame's name, length and comment,
//! the triggering's identifier, addressing mode and CAN FD behaviour. Its PDU gives the
//! signals: an I-signal PDU its mapped I-signals (start position as DBC's start bit, byte
//! order, base type, the system signal's compu method as scaling, range and value names, unit,
//! comment, initial value); a multiplexed PDU a selector signal `<frame>_selector<n>` with the
//! dynamic parts' signals multiplexed by it and the static part's signals; a secured PDU its
//! payload's signals, the truncated freshness value and authenticator as the signals
//! `<pdu>_Freshness` and `<pdu>_Authenticator`, and its SecOC properties as the `SecOC…`
//! attributes [`crate::secoc`] reads; a container PDU the PDUs it may carry, each behind its
//! header ([`Container`]). E2E protection (a protection set, or a signal group's E2E
//! transformer) becomes the counter and checksum attributes [`crate::e2e`] reads when the
//! profile is one bywire computes, and a warning otherwise. Cycle times become
//! `GenMsgCycleTime`, CAN FD frames `VFrameFormat`; ECU instances are the nodes, and their PDU
//! groups' directions (and the network-management nodes' PDUs) the senders and receivers.
//!
//! References are resolved by absolute path, or relative to a package's reference base. A
//! system with several CAN clusters loads all of them, each message's cluster in its `BusName`
//! attribute, or only the one [`read`] is asked for.

use std::collections::HashMap;

use roxmltree::{Document, Node as XmlNode, NodeId};

use crate::format::{attrs, plain_signal, LineIndex, Report, NO_NODE};
use crate::model::*;
use crate::parser::{Diagnostic, Mode, ParseError, Severity};
use crate::xml::{child, children};

/// Elements a file may hold before it is refused (a 10 MB file has about a quarter million).
const MAX_NODES: u32 = 50_000_000;

/// How deep PDUs may nest (a container of secured multiplexed PDUs is three): a reference
/// cycle ends here instead of exhausting the stack.
const MAX_PDU_DEPTH: u32 = 8;

/// The attribute naming a message's cluster when a file's clusters are loaded together.
pub const BUS_NAME: &str = "BusName";

/// Read ARXML text: every CAN cluster, or only the one named `bus`.
pub(crate) fn read(
    text: &str,
    mode: Mode,
    bus: Option<&str>,
) -> Result<(Database, Vec<Diagnostic>), ParseError> {
    let doc = crate::xml::parse(text, false, MAX_NODES)?;
    let root = doc.root_element();
    let lines = LineIndex::new(text);
    let version = version_of(&lines, root)?;
    let mut reader = Reader {
        doc: &doc,
        lines: &lines,
        report: Report::new(mode),
        version,
        by_path: HashMap::new(),
        path_of: HashMap::new(),
    };
    reader.index(root)?;
    let db = reader.database(root, bus)?;
    reader.report.finish(db)
}

/// The AUTOSAR major version the root element's namespace names (3 or 4).
fn version_of(lines: &LineIndex<'_>, root: XmlNode<'_, '_>) -> Result<u8, ParseError> {
    let at = lines.position(root.range().start);
    let namespace = root.tag_name().namespace().unwrap_or_default();
    if root.tag_name().name() != "AUTOSAR" {
        return Err(Report::fatal(
            at,
            format!(
                "the root element is {}, not AUTOSAR",
                root.tag_name().name()
            ),
        ));
    }
    let release = namespace
        .strip_prefix("http://autosar.org/schema/r")
        .or_else(|| namespace.strip_prefix("http://autosar.org/"))
        .map(|r| r.split(".DAI.").next().unwrap_or(r))
        .filter(|r| !r.is_empty() && r.split('.').all(|p| p.parse::<u32>().is_ok()))
        .filter(|r| r.split('.').count() <= 3);
    match release.and_then(|r| r.split('.').next()) {
        Some("4") => Ok(4),
        Some("3") => Ok(3),
        _ => Err(Report::fatal(
            at,
            format!("the namespace \"{namespace}\" is not AUTOSAR 3 or 4's"),
        )),
    }
}

/// An element's text, trimmed; `None` when it has none.
fn text<'a>(n: XmlNode<'a, '_>) -> Option<&'a str> {
    n.text().map(str::trim).filter(|t| !t.is_empty())
}

fn short_name<'a>(n: XmlNode<'a, '_>) -> Option<&'a str> {
    child(n, "SHORT-NAME").and_then(text)
}

fn is(n: XmlNode<'_, '_>, tag: &str) -> bool {
    n.tag_name().name() == tag
}

/// A number as ARXML writes it: decimal, `0x` hex, `0b` binary, C octal (a leading 0),
/// `true`/`false`, or a float.
fn number(text: &str) -> Option<Num> {
    let t = text.trim().to_ascii_lowercase();
    let int = |digits: &str, radix| i128::from_str_radix(digits, radix).ok().map(Num::Int);
    match t.as_str() {
        "true" => return Some(Num::Int(1)),
        "false" => return Some(Num::Int(0)),
        _ => {}
    }
    let (negative, body) = match t.strip_prefix('-') {
        Some(rest) => (true, rest),
        None => (false, t.strip_prefix('+').unwrap_or(&t)),
    };
    let magnitude = if let Some(hex) = body.strip_prefix("0x") {
        int(hex, 16)
    } else if let Some(bin) = body.strip_prefix("0b") {
        int(bin, 2)
    } else if let Some(oct) = body.strip_prefix("0o") {
        int(oct, 8)
    } else if body.len() > 1 && body.starts_with('0') && body.bytes().all(|b| b.is_ascii_digit()) {
        int(body, 8)
    } else {
        int(body, 10)
    };
    match magnitude {
        Some(Num::Int(v)) => Some(Num::Int(if negative { -v } else { v })),
        _ => t
            .parse::<f64>()
            .ok()
            .filter(|f| f.is_finite())
            .map(Num::Float),
    }
}

/// A number that must be a whole one (`123.0` counts, as AUTOSAR tools write it).
fn whole(text: &str) -> Option<i128> {
    match number(text)? {
        Num::Int(i) => Some(i),
        Num::Float(f) => crate::decoder::integral(f),
    }
}

/// A message read from a frame or a contained PDU, with the paths of the PDUs it carries (how
/// ECU instances and protection sets name it).
struct Unit {
    message: Message,
    pdu_paths: Vec<String>,
    /// The E2E protection its signal group declares, when one does.
    e2e: Option<E2e>,
    /// Where it goes: a frame of the database, or a PDU of the container at that index.
    container: Option<usize>,
}

/// A declared E2E protection.
#[derive(Clone)]
struct E2e {
    profile: String,
    data_ids: Vec<i128>,
    crc_offset: Option<u32>,
    counter_offset: Option<u32>,
    /// How the data ID enters the CRC (`ALL-16-BIT`: both bytes, low first).
    data_id_mode: Option<String>,
    at: Position,
}

/// What a PDU gives its message.
#[derive(Default)]
struct Pdu {
    length: Option<u32>,
    signals: Vec<Signal>,
    cycle_ms: Option<i128>,
    child_paths: Vec<String>,
    attributes: Vec<(String, AttrValue)>,
    e2e: Option<E2e>,
    /// A container's header and the PDUs it carries.
    contained: Option<(ContainerHeader, Vec<Unit>)>,
}

struct Reader<'a, 'input> {
    doc: &'a Document<'input>,
    lines: &'a LineIndex<'input>,
    report: Report,
    version: u8,
    by_path: HashMap<String, NodeId>,
    path_of: HashMap<NodeId, String>,
}

impl<'a, 'input> Reader<'a, 'input> {
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

    fn warning(
        &mut self,
        n: XmlNode<'_, 'input>,
        message: impl Into<String>,
        resolution: &str,
    ) -> Result<(), ParseError> {
        let at = self.at(n);
        self.report.add(Severity::Warning, at, message, resolution)
    }

    /// Every element with a short name by its path, and back.
    fn index(&mut self, root: XmlNode<'a, 'input>) -> Result<(), ParseError> {
        // The path of the nearest named ancestor-or-self of each element seen, found by
        // walking up to an element already indexed: parents come before children.
        for n in root.descendants().filter(XmlNode::is_element) {
            let Some(name) = short_name(n) else { continue };
            let parent_path = n
                .ancestors()
                .skip(1)
                .find_map(|a| self.path_of.get(&a.id()))
                .map_or("", String::as_str);
            let path = format!("{parent_path}/{name}");
            if self.by_path.contains_key(&path) {
                self.warning(
                    n,
                    format!("a second element with the path {path}"),
                    "references reach the first",
                )?;
            } else {
                self.by_path.insert(path.clone(), n.id());
            }
            self.path_of.insert(n.id(), path);
        }
        Ok(())
    }

    fn path(&self, n: XmlNode<'_, 'input>) -> String {
        self.path_of.get(&n.id()).cloned().unwrap_or_default()
    }

    /// The absolute path a reference element names: as written, or after its package's
    /// reference base (`BASE`, else the default one) when relative.
    fn absolute(&self, r: XmlNode<'a, 'input>) -> Option<String> {
        let target = text(r)?;
        if target.starts_with('/') {
            return Some(target.to_string());
        }
        let label = r.attribute("BASE");
        r.ancestors()
            .filter(|a| is(*a, "AR-PACKAGE"))
            .flat_map(|p| child(p, "REFERENCE-BASES").into_iter())
            .flat_map(|bases| children(bases, "REFERENCE-BASE"))
            .find(|b| match label {
                Some(l) => child(*b, "SHORT-LABEL").and_then(text) == Some(l),
                None => child(*b, "IS-DEFAULT").and_then(text) == Some("true"),
            })
            .and_then(|b| child(b, "PACKAGE-REF").and_then(text))
            .map(|base| format!("{}/{target}", base.trim_end_matches('/')))
    }

    /// The element a reference element names; a dangling one is reported.
    fn resolve(
        &mut self,
        r: XmlNode<'a, 'input>,
    ) -> Result<Option<XmlNode<'a, 'input>>, ParseError> {
        let found = self
            .absolute(r)
            .and_then(|p| self.by_path.get(&p).copied())
            .and_then(|id| self.doc.get_node(id));
        let dest = r.attribute("DEST");
        match found {
            Some(n) if dest.is_none_or(|d| is(n, d)) => Ok(Some(n)),
            Some(n) => {
                // The path names one element; DEST only says what the writer thought it was.
                self.warning(
                    r,
                    format!(
                        "{} {} names a {}, not the {} it says",
                        r.tag_name().name(),
                        text(r).unwrap_or_default(),
                        n.tag_name().name(),
                        dest.unwrap_or_default()
                    ),
                    "followed to what the path names",
                )?;
                Ok(Some(n))
            }
            None => {
                self.problem(
                    r,
                    format!(
                        "dangling reference {} to {}",
                        r.tag_name().name(),
                        text(r).unwrap_or_default()
                    ),
                    "reference skipped",
                )?;
                Ok(None)
            }
        }
    }

    /// The child `tag` of `n`, written in place or referenced by a `tag-REF` child.
    fn follow(
        &mut self,
        n: XmlNode<'a, 'input>,
        tag: &str,
    ) -> Result<Option<XmlNode<'a, 'input>>, ParseError> {
        if let Some(c) = child(n, tag) {
            return Ok(Some(c));
        }
        match child(n, &format!("{tag}-REF")) {
            Some(r) => self.resolve(r),
            None => Ok(None),
        }
    }

    /// Every child `tag` of `n`, in place or referenced.
    fn follow_all(
        &mut self,
        n: XmlNode<'a, 'input>,
        tag: &str,
    ) -> Result<Vec<XmlNode<'a, 'input>>, ParseError> {
        let reference = format!("{tag}-REF");
        let mut out = Vec::new();
        for c in n.children().filter(XmlNode::is_element) {
            if is(c, tag) {
                out.push(c);
            } else if is(c, &reference) {
                out.extend(self.resolve(c)?);
            }
        }
        Ok(out)
    }

    /// The element at the end of `steps` from `n`, each step in place or referenced.
    fn walk(
        &mut self,
        n: XmlNode<'a, 'input>,
        steps: &[&str],
    ) -> Result<Option<XmlNode<'a, 'input>>, ParseError> {
        let mut here = n;
        for step in steps {
            match self.follow(here, step)? {
                Some(next) => here = next,
                None => return Ok(None),
            }
        }
        Ok(Some(here))
    }

    /// Every element reached by `steps` from `n`, each step taking all matches.
    fn walk_all(
        &mut self,
        n: XmlNode<'a, 'input>,
        steps: &[&str],
    ) -> Result<Vec<XmlNode<'a, 'input>>, ParseError> {
        let mut here = vec![n];
        for step in steps {
            let mut next = Vec::new();
            for h in here {
                next.extend(self.follow_all(h, step)?);
            }
            here = next;
        }
        Ok(here)
    }

    /// A whole number at `steps` from `n`; a present but unreadable one is reported.
    fn whole_at(
        &mut self,
        n: XmlNode<'a, 'input>,
        steps: &[&str],
    ) -> Result<Option<i128>, ParseError> {
        let Some(e) = self.walk(n, steps)? else {
            return Ok(None);
        };
        let value = text(e).and_then(whole);
        if value.is_none() {
            self.problem(
                e,
                format!(
                    "{} \"{}\" is not a whole number",
                    e.tag_name().name(),
                    text(e).unwrap_or_default()
                ),
                "left out",
            )?;
        }
        Ok(value)
    }

    fn database(
        &mut self,
        root: XmlNode<'a, 'input>,
        bus: Option<&str>,
    ) -> Result<Database, ParseError> {
        if root.descendants().any(|n| is(n, "ECUC-VALUE-COLLECTION"))
            && !root.descendants().any(|n| is(n, "CAN-CLUSTER"))
        {
            return self.ecu_extract(root);
        }
        let mut clusters: Vec<XmlNode<'a, 'input>> = root
            .descendants()
            .filter(|n| is(*n, "CAN-CLUSTER"))
            .collect();
        if let Some(wanted) = bus {
            let names: Vec<&str> = clusters.iter().filter_map(|c| short_name(*c)).collect();
            clusters.retain(|c| short_name(*c) == Some(wanted));
            if clusters.is_empty() {
                return Err(Report::fatal(
                    self.at(root),
                    format!(
                        "no CAN cluster named {wanted} (the file has {})",
                        if names.is_empty() {
                            "none".to_string()
                        } else {
                            names.join(", ")
                        }
                    ),
                ));
            }
        }
        let several = clusters.len() > 1;
        let mut db = Database::default();
        let mut units: Vec<Unit> = Vec::new();
        for cluster in &clusters {
            let cluster_name = short_name(*cluster).unwrap_or_default().to_string();
            if !several {
                db.comment = self.comment(*cluster);
                db.attributes
                    .push(("DBName".to_string(), AttrValue::Str(cluster_name.clone())));
            }
            let triggerings: Vec<XmlNode<'a, 'input>> = cluster
                .descendants()
                .filter(|n| is(*n, "CAN-FRAME-TRIGGERING"))
                .collect();
            for t in triggerings {
                let first = units.len();
                self.frame(t, &mut units, &mut db.containers)?;
                if several {
                    // The frame's own unit (a container's PDUs follow it).
                    if let Some(unit) = units.get_mut(first) {
                        unit.message
                            .attributes
                            .push((BUS_NAME.to_string(), AttrValue::Str(cluster_name.clone())));
                    }
                }
            }
        }
        let ecus: Vec<XmlNode<'a, 'input>> = root
            .descendants()
            .filter(|n| is(*n, "ECU-INSTANCE"))
            .collect();
        for ecu in &ecus {
            db.nodes.push(Node {
                name: short_name(*ecu).unwrap_or_default().to_string(),
                comment: self.comment(*ecu),
                attributes: Vec::new(),
            });
        }
        for ecu in ecus {
            self.senders_and_receivers(ecu, &mut units)?;
        }
        self.network_management(root, &mut units)?;
        self.protection_sets(root, &mut units)?;
        let header_byte_order = match root
            .descendants()
            .find(|n| is(*n, "CONTAINER-I-PDU-HEADER-BYTE-ORDER"))
            .and_then(text)
        {
            Some("MOST-SIGNIFICANT-BYTE-LAST") => ByteOrder::LittleEndian,
            _ => ByteOrder::BigEndian,
        };
        for unit in units {
            let Unit {
                mut message,
                e2e,
                container,
                ..
            } = unit;
            if let Some(e2e) = e2e {
                self.declare_e2e(&mut message, &e2e)?;
            }
            match container.and_then(|i| db.containers.get_mut(i)) {
                Some(c) => c.pdus.push(message),
                None => db.messages.push(message),
            }
        }
        for c in &mut db.containers {
            c.header_byte_order = header_byte_order;
        }
        define_attributes(&mut db);
        Ok(db)
    }

    /// An ECU extract of ECUC values: the Com module's I-PDUs as messages, their identifiers,
    /// lengths and formats from the CanIf module's PDU configurations, their signals' layout
    /// and type from the Com signals.
    fn ecu_extract(&mut self, root: XmlNode<'a, 'input>) -> Result<Database, ParseError> {
        let containers: Vec<XmlNode<'a, 'input>> = root
            .descendants()
            .filter(|n| is(*n, "ECUC-CONTAINER-VALUE"))
            .collect();
        let defined = |n: XmlNode<'_, '_>, kind: &str| {
            child(n, "DEFINITION-REF")
                .and_then(text)
                .is_some_and(|d| d.rsplit('/').next() == Some(kind))
        };
        let mut db = Database::default();
        for pdu in containers.iter().filter(|c| defined(**c, "ComIPdu")) {
            let name = short_name(*pdu).unwrap_or_default().to_string();
            let direction = parameter(*pdu, "ComIPduDirection");
            let Some(pdu_ref) = reference(*pdu, "ComPduIdRef") else {
                self.problem(
                    *pdu,
                    format!("Com I-PDU {name} has no ComPduIdRef"),
                    "left out",
                )?;
                continue;
            };
            let (config, link, prefix) = match direction {
                Some("SEND") => ("CanIfTxPduCfg", "CanIfTxPduRef", "CanIfTxPdu"),
                Some("RECEIVE") => ("CanIfRxPduCfg", "CanIfRxPduRef", "CanIfRxPdu"),
                other => {
                    self.problem(
                        *pdu,
                        format!(
                            "Com I-PDU {name}'s direction is {}, not SEND or RECEIVE",
                            other.unwrap_or("missing")
                        ),
                        "left out",
                    )?;
                    continue;
                }
            };
            let can_if = containers
                .iter()
                .find(|c| defined(**c, config) && reference(**c, link) == Some(pdu_ref));
            let param = |key: &str| can_if.and_then(|c| parameter(*c, &format!("{prefix}{key}")));
            let id = param("CanId")
                .and_then(whole)
                .and_then(|v| u32::try_from(v).ok());
            let size = param("Dlc")
                .and_then(whole)
                .and_then(|v| u32::try_from(v).ok());
            let extended = param("CanIdType").map(|t| t == "EXTENDED_CAN");
            let (Some(id), Some(size), Some(extended)) = (id, size, extended) else {
                self.warning(
                    *pdu,
                    format!("Com I-PDU {name} has no CanIf identifier, length and type"),
                    "left out",
                )?;
                continue;
            };
            let mut signals = Vec::new();
            for target in references(*pdu, "ComIPduSignalRef") {
                let Some(signal) = self
                    .by_path
                    .get(target)
                    .and_then(|id| self.doc.get_node(*id))
                else {
                    self.problem(
                        *pdu,
                        format!("dangling ComIPduSignalRef to {target}"),
                        "left out",
                    )?;
                    continue;
                };
                signals.extend(self.com_signal(signal)?);
            }
            db.messages.push(Message {
                id,
                extended,
                name,
                size,
                transmitter: NO_NODE.to_string(),
                senders: Vec::new(),
                signals,
                comment: None,
                attributes: Vec::new(),
                position: self.at(*pdu),
            });
        }
        define_attributes(&mut db);
        Ok(db)
    }

    /// A Com signal of an ECU extract.
    fn com_signal(&mut self, n: XmlNode<'a, 'input>) -> Result<Option<Signal>, ParseError> {
        let name = short_name(n).unwrap_or_default().to_string();
        let count = |key| {
            parameter(n, key)
                .and_then(whole)
                .and_then(|v| u32::try_from(v).ok())
        };
        let (Some(start), Some(length)) = (
            count("ComBitPosition").filter(|s| *s < 512),
            count("ComBitSize").filter(|l| (1..=64).contains(l)),
        ) else {
            self.problem(
                n,
                format!("Com signal {name} needs a ComBitPosition below 512 and a ComBitSize of 1 to 64"),
                "left out",
            )?;
            return Ok(None);
        };
        let byte_order = match parameter(n, "ComSignalEndianness") {
            Some("BIG_ENDIAN") => ByteOrder::BigEndian,
            _ => ByteOrder::LittleEndian,
        };
        let mut s = plain_signal(
            name,
            (start, length, byte_order),
            Multiplexing::None,
            self.at(n),
        );
        s.value_type = match parameter(n, "ComSignalType") {
            Some(t) if t.starts_with("SINT") => ValueType::Integer { signed: true },
            Some("FLOAT32") if length == 32 => ValueType::Float32,
            Some("FLOAT64") if length == 64 => ValueType::Float64,
            _ => s.value_type,
        };
        if let Some(v) = parameter(n, "ComSignalInitValue").and_then(number) {
            s.attributes
                .push((attrs::START_VALUE.to_string(), AttrValue::Number(v)));
        }
        Ok(Some(s))
    }

    /// A comment from `DESC`: the `FOR-ALL` language's, else English, else the first.
    fn comment(&self, n: XmlNode<'a, 'input>) -> Option<String> {
        let desc = child(n, "DESC")?;
        let texts: Vec<(Option<&str>, String)> = children(desc, "L-2")
            .filter_map(|l| {
                let t = l.text()?;
                let lines: Vec<&str> = t.split('\n').map(str::trim).collect();
                Some((l.attribute("L"), lines.join("\n")))
            })
            .collect();
        let pick = |lang: &str| {
            texts
                .iter()
                .find(|(l, _)| l.unwrap_or("EN") == lang)
                .map(|(_, t)| t.clone())
        };
        pick("FOR-ALL")
            .or_else(|| pick("EN"))
            .or_else(|| texts.first().map(|(_, t)| t.clone()))
    }

    /// A frame triggering: its message (or container) and what its PDU carries.
    fn frame(
        &mut self,
        t: XmlNode<'a, 'input>,
        units: &mut Vec<Unit>,
        containers: &mut Vec<Container>,
    ) -> Result<(), ParseError> {
        let Some(frame) = self.follow(t, "FRAME")? else {
            self.problem(t, "a frame triggering without a frame", "skipped")?;
            return Ok(());
        };
        let name = short_name(frame).unwrap_or_default().to_string();
        let extended = child(t, "CAN-ADDRESSING-MODE").and_then(text) == Some("EXTENDED");
        let Some(id) = self.whole_at(t, &["IDENTIFIER"])? else {
            self.problem(t, format!("frame {name} has no identifier"), "skipped")?;
            return Ok(());
        };
        let limit = crate::format::id_limit(extended);
        let Some(id) = u32::try_from(id).ok().filter(|id| *id <= limit) else {
            self.problem(
                t,
                format!("frame {name}'s identifier {id} is too large for its format"),
                "skipped",
            )?;
            return Ok(());
        };
        let size = match self.whole_at(frame, &["FRAME-LENGTH"])? {
            Some(n) if (0..=64).contains(&n) => u32::try_from(n).unwrap_or(0),
            Some(n) => {
                self.problem(
                    frame,
                    format!("frame {name}'s length {n} is not 0 to 64 bytes"),
                    "skipped",
                )?;
                return Ok(());
            }
            None => 0,
        };
        let behaviour = |tag| child(t, tag).and_then(text) == Some("CAN-FD");
        let fd = behaviour("CAN-FRAME-TX-BEHAVIOR") || behaviour("CAN-FRAME-RX-BEHAVIOR");
        let mut message = Message {
            id,
            extended,
            name: name.clone(),
            size,
            transmitter: NO_NODE.to_string(),
            senders: Vec::new(),
            signals: Vec::new(),
            comment: self.comment(frame),
            attributes: Vec::new(),
            position: self.at(t),
        };
        if fd {
            let format = usize::from(extended) + 2;
            message.attributes.push((
                attrs::FRAME_FORMAT.to_string(),
                AttrValue::Number(Num::Int(i128::try_from(format).unwrap_or(2))),
            ));
        }
        let mapping = self.walk(frame, &["PDU-TO-FRAME-MAPPINGS", "PDU-TO-FRAME-MAPPING"])?;
        let pdu = match mapping {
            Some(m) => self.follow(m, "PDU")?,
            None => None,
        };
        let Some(pdu) = pdu else {
            units.push(Unit {
                message,
                pdu_paths: Vec::new(),
                e2e: None,
                container: None,
            });
            return Ok(());
        };
        let mut selectors = 0;
        let loaded = self.pdu(pdu, (&name, &name), &mut selectors, 0)?;
        let mut pdu_paths = vec![self.path(pdu)];
        pdu_paths.extend(loaded.child_paths);
        if let Some((header, contained)) = loaded.contained {
            let index = containers.len();
            containers.push(Container {
                message: name,
                header,
                header_byte_order: ByteOrder::BigEndian,
                pdus: Vec::new(),
            });
            units.push(Unit {
                message,
                pdu_paths,
                e2e: None,
                container: None,
            });
            units.extend(contained.into_iter().map(|u| Unit {
                container: Some(index),
                ..u
            }));
            return Ok(());
        }
        message.signals = loaded.signals;
        message.attributes.extend(loaded.attributes);
        if let Some(ms) = loaded.cycle_ms {
            message.attributes.push((
                attrs::CYCLE_TIME.to_string(),
                AttrValue::Number(Num::Int(ms)),
            ));
        }
        units.push(Unit {
            message,
            pdu_paths,
            e2e: loaded.e2e,
            container: None,
        });
        Ok(())
    }

    /// What a PDU carries; `names` are the frame's (which names the selector signals of
    /// multiplexed PDUs) and the message's (which names a secured PDU's freshness and
    /// authenticator signals).
    fn pdu(
        &mut self,
        pdu: XmlNode<'a, 'input>,
        names: (&str, &str),
        selectors: &mut u32,
        depth: u32,
    ) -> Result<Pdu, ParseError> {
        if depth >= MAX_PDU_DEPTH {
            self.problem(
                pdu,
                format!("PDUs nest more than {MAX_PDU_DEPTH} deep (a reference cycle?)"),
                "the inner PDU left out",
            )?;
            return Ok(Pdu::default());
        }
        let length = self.pdu_length(pdu)?;
        match pdu.tag_name().name() {
            "CONTAINER-I-PDU" => self.container(pdu, names.0, selectors, depth, length),
            "SECURED-I-PDU" => self.secured(pdu, names, selectors, depth),
            tag => {
                let mut out = Pdu {
                    length,
                    cycle_ms: self.cycle_time(pdu)?,
                    e2e: self.signal_group_e2e(pdu)?,
                    ..Pdu::default()
                };
                out.signals = self.pdu_signals(pdu)?;
                if tag == "MULTIPLEXED-I-PDU" {
                    self.multiplexed(pdu, names, selectors, depth, &mut out)?;
                }
                Ok(out)
            }
        }
    }

    fn container(
        &mut self,
        pdu: XmlNode<'a, 'input>,
        frame: &str,
        selectors: &mut u32,
        depth: u32,
        length: Option<u32>,
    ) -> Result<Pdu, ParseError> {
        let header = match child(pdu, "HEADER-TYPE").and_then(text) {
            Some("SHORT-HEADER") => ContainerHeader::Short,
            Some("LONG-HEADER") => ContainerHeader::Long,
            other => {
                self.problem(
                    pdu,
                    format!(
                        "container PDU {} has header type {}: bywire reads short and long headers",
                        short_name(pdu).unwrap_or_default(),
                        other.unwrap_or("none")
                    ),
                    "its PDUs left out",
                )?;
                return Ok(Pdu {
                    length,
                    ..Pdu::default()
                });
            }
        };
        let header_tag = match header {
            ContainerHeader::Short => "HEADER-ID-SHORT-HEADER",
            ContainerHeader::Long => "HEADER-ID-LONG-HEADER",
        };
        let mut units = Vec::new();
        let mut child_paths = Vec::new();
        let triggerings = self.walk_all(
            pdu,
            &["CONTAINED-PDU-TRIGGERING-REFS", "CONTAINED-PDU-TRIGGERING"],
        )?;
        for t in triggerings {
            let Some(inner) = self.follow(t, "I-PDU")? else {
                continue;
            };
            let name = short_name(inner).unwrap_or_default().to_string();
            let Some(header_id) = self.whole_at(inner, &["CONTAINED-I-PDU-PROPS", header_tag])?
            else {
                self.problem(
                    inner,
                    format!("contained PDU {name} has no {header_tag}"),
                    "left out",
                )?;
                continue;
            };
            let Ok(header_id) = u32::try_from(header_id) else {
                self.problem(
                    inner,
                    format!("contained PDU {name}'s header identifier {header_id} is out of range"),
                    "left out",
                )?;
                continue;
            };
            let loaded = self.pdu(inner, (frame, &name), selectors, depth + 1)?;
            if loaded.contained.is_some() {
                self.problem(
                    inner,
                    format!("container PDU {name} inside a container"),
                    "left out",
                )?;
                continue;
            }
            let path = self.path(inner);
            let mut pdu_paths = vec![path];
            pdu_paths.extend(loaded.child_paths);
            child_paths.extend(pdu_paths.iter().cloned());
            let mut message = Message {
                id: header_id,
                extended: false,
                name,
                size: loaded.length.unwrap_or(0),
                transmitter: NO_NODE.to_string(),
                senders: Vec::new(),
                signals: loaded.signals,
                comment: self.comment(inner),
                attributes: loaded.attributes,
                position: self.at(inner),
            };
            if let Some(ms) = loaded.cycle_ms {
                message.attributes.push((
                    attrs::CYCLE_TIME.to_string(),
                    AttrValue::Number(Num::Int(ms)),
                ));
            }
            units.push(Unit {
                message,
                pdu_paths,
                e2e: loaded.e2e,
                container: None,
            });
        }
        Ok(Pdu {
            length,
            child_paths,
            contained: Some((header, units)),
            ..Pdu::default()
        })
    }

    /// A secured PDU: its payload's signals, the truncated freshness value and MAC as signals,
    /// and its SecOC properties as attributes.
    fn secured(
        &mut self,
        pdu: XmlNode<'a, 'input>,
        names: (&str, &str),
        selectors: &mut u32,
        depth: u32,
    ) -> Result<Pdu, ParseError> {
        let name = names.1.to_string();
        // AUTOSAR 4.3 names a PDU triggering as the payload (which names the PDU), 4.2 the
        // PDU itself.
        let payload = match self.follow(pdu, "PAYLOAD")? {
            Some(p) if !p.tag_name().name().ends_with("PDU") => self.follow(p, "I-PDU")?,
            other => other,
        };
        let Some(payload) = payload else {
            self.problem(
                pdu,
                format!("secured PDU {name} has no payload"),
                "left out",
            )?;
            return Ok(Pdu::default());
        };
        let mut out = self.pdu(payload, names, selectors, depth + 1)?;
        out.child_paths.push(self.path(payload));
        if out.e2e.is_none() {
            out.e2e = self.signal_group_e2e(pdu)?;
        }
        let payload_length = out.length.unwrap_or(0);
        out.length = self.pdu_length(pdu)?;
        if out.cycle_ms.is_none() {
            out.cycle_ms = self.cycle_time(pdu)?;
        }
        let data_id = self.whole_at(pdu, &["SECURE-COMMUNICATION-PROPS", "DATA-ID"])?;
        let fv_length = self.whole_at(pdu, &["FRESHNESS-PROPS", "FRESHNESS-VALUE-LENGTH"])?;
        let fv_tx = self.whole_at(pdu, &["FRESHNESS-PROPS", "FRESHNESS-VALUE-TX-LENGTH"])?;
        let mac_tx = self.whole_at(pdu, &["AUTHENTICATION-PROPS", "AUTH-INFO-TX-LENGTH"])?;
        let start = payload_length.saturating_mul(8);
        let fv_bits = fv_tx.and_then(|n| u32::try_from(n).ok()).unwrap_or(0);
        let mut truncated = |suffix: &str, network_start: u32, length: u32| {
            if length == 0 || length > 64 || network_start >= 512 {
                return;
            }
            let mut s = plain_signal(
                format!("{name}_{suffix}"),
                (
                    crate::format::start_bit_from_network(ByteOrder::BigEndian, network_start),
                    length,
                    ByteOrder::BigEndian,
                ),
                Multiplexing::None,
                Position::default(),
            );
            s.comment = Some(format!(
                "Truncated {} value for '{name}'",
                if suffix == "Freshness" {
                    "freshness"
                } else {
                    "authenticator"
                }
            ));
            out.signals.push(s);
        };
        truncated("Freshness", start, fv_bits);
        let mac_bits = mac_tx.and_then(|n| u32::try_from(n).ok()).unwrap_or(0);
        truncated("Authenticator", start.saturating_add(fv_bits), mac_bits);
        let algorithm = self
            .walk(pdu, &["AUTHENTICATION-PROPS", "AUTH-ALGORITHM"])?
            .and_then(text)
            .map(str::to_string);
        if let Some(a) = algorithm.filter(|a| !a.to_ascii_uppercase().contains("CMAC")) {
            self.warning(
                pdu,
                format!("secured PDU {name} authenticates with {a}: bywire verifies AES-128 CMACs"),
                "verification will not match",
            )?;
        }
        match (data_id, fv_length, fv_tx, mac_tx) {
            (Some(id), Some(fv), Some(tx), Some(mac)) => {
                let int = |v: i128| AttrValue::Number(Num::Int(v));
                out.attributes.extend([
                    ("SecOCDataId".to_string(), int(id)),
                    ("SecOCFreshnessValueLength".to_string(), int(fv)),
                    ("SecOCFreshnessValueTxLength".to_string(), int(tx)),
                    ("SecOCAuthInfoTxLength".to_string(), int(mac)),
                    (
                        "SecOCAuthenticPduLength".to_string(),
                        int(i128::from(payload_length)),
                    ),
                ]);
            }
            _ => self.warning(
                pdu,
                format!(
                    "secured PDU {name} lacks a data ID, freshness value lengths or an \
                     authenticator length"
                ),
                "its MAC is not verified",
            )?,
        }
        Ok(out)
    }

    /// The dynamic parts of a multiplexed PDU, multiplexed by a selector signal, and its static
    /// part.
    fn multiplexed(
        &mut self,
        pdu: XmlNode<'a, 'input>,
        names: (&str, &str),
        selectors: &mut u32,
        depth: u32,
        out: &mut Pdu,
    ) -> Result<(), ParseError> {
        let (Some(position), Some(length)) = (
            self.whole_at(pdu, &["SELECTOR-FIELD-START-POSITION"])?,
            self.whole_at(pdu, &["SELECTOR-FIELD-LENGTH"])?,
        ) else {
            self.problem(
                pdu,
                "a multiplexed PDU without a selector field position and length",
                "its dynamic part left out",
            )?;
            return Ok(());
        };
        let (Ok(position), Ok(length)) = (u32::try_from(position), u32::try_from(length)) else {
            self.problem(pdu, "the selector field lies outside the PDU", "left out")?;
            return Ok(());
        };
        let byte_order = match child(pdu, "SELECTOR-FIELD-BYTE-ORDER").and_then(text) {
            Some("MOST-SIGNIFICANT-BYTE-FIRST") => ByteOrder::BigEndian,
            _ => ByteOrder::LittleEndian,
        };
        *selectors += 1;
        let mut selector = plain_signal(
            format!("{}_selector{selectors}", names.0),
            (position, length, byte_order),
            Multiplexing::Multiplexor,
            self.at(pdu),
        );
        let mut dynamic: Vec<Signal> = Vec::new();
        let alternatives = if self.version >= 4 {
            self.walk_all(
                pdu,
                &[
                    "DYNAMIC-PARTS",
                    "DYNAMIC-PART",
                    "DYNAMIC-PART-ALTERNATIVES",
                    "DYNAMIC-PART-ALTERNATIVE",
                ],
            )?
        } else {
            self.walk_all(
                pdu,
                &[
                    "DYNAMIC-PART",
                    "DYNAMIC-PART-ALTERNATIVES",
                    "DYNAMIC-PART-ALTERNATIVE",
                ],
            )?
        };
        for alternative in alternatives {
            let Some(code) = self.whole_at(alternative, &["SELECTOR-FIELD-CODE"])? else {
                self.problem(
                    alternative,
                    "a dynamic part without a selector code",
                    "left out",
                )?;
                continue;
            };
            let Some(part) = self.follow(alternative, "I-PDU")? else {
                continue;
            };
            let Ok(code) = u64::try_from(code) else {
                self.problem(
                    alternative,
                    format!("selector code {code} is negative"),
                    "left out",
                )?;
                continue;
            };
            if child(alternative, "INITIAL-DYNAMIC-PART").and_then(text) == Some("true") {
                selector.attributes.push((
                    attrs::START_VALUE.to_string(),
                    AttrValue::Number(Num::Int(i128::from(code))),
                ));
            }
            out.child_paths.push(self.path(part));
            let loaded = self.pdu(part, names, selectors, depth + 1)?;
            out.child_paths.extend(loaded.child_paths);
            if let Some(ms) = loaded.cycle_ms {
                out.cycle_ms = Some(out.cycle_ms.map_or(ms, |c| c.min(ms)));
            }
            for mut s in loaded.signals {
                // The selector is mapped into every part as well: it is the multiplexor.
                if s.start_bit == position && s.length == length {
                    for (value, description) in s.value_descriptions {
                        if !selector.value_descriptions.iter().any(|(v, _)| *v == value) {
                            selector.value_descriptions.push((value, description));
                        }
                    }
                    continue;
                }
                match s.multiplexing {
                    Multiplexing::None => s.multiplexing = Multiplexing::Multiplexed(code),
                    _ => {
                        self.warning(
                            part,
                            format!(
                                "signal {} is multiplexed twice over (a multiplexed PDU in a \
                                 multiplexed PDU)",
                                s.name
                            ),
                            "kept under its inner selector only",
                        )?;
                    }
                }
                dynamic.push(s);
            }
        }
        let statics = if self.version >= 4 {
            self.walk_all(pdu, &["STATIC-PARTS", "STATIC-PART", "I-PDU"])?
        } else {
            self.walk_all(pdu, &["STATIC-PART", "I-PDU"])?
        };
        let mut static_signals = Vec::new();
        for part in statics {
            out.child_paths.push(self.path(part));
            let loaded = self.pdu(part, names, selectors, depth + 1)?;
            out.child_paths.extend(loaded.child_paths);
            static_signals.extend(loaded.signals);
        }
        out.signals.push(selector);
        out.signals.extend(dynamic);
        out.signals.extend(static_signals);
        Ok(())
    }

    /// A PDU's length in bytes (AUTOSAR 3 gives it in bits).
    fn pdu_length(&mut self, pdu: XmlNode<'a, 'input>) -> Result<Option<u32>, ParseError> {
        let length = self
            .whole_at(pdu, &["LENGTH"])?
            .and_then(|n| u32::try_from(n).ok());
        Ok(if self.version < 4 {
            length.map(|bits| bits.div_ceil(8))
        } else {
            length
        })
    }

    /// The PDU's cycle time in milliseconds.
    fn cycle_time(&mut self, pdu: XmlNode<'a, 'input>) -> Result<Option<i128>, ParseError> {
        let steps: &[&str] = if self.version >= 4 {
            &[
                "I-PDU-TIMING-SPECIFICATIONS",
                "I-PDU-TIMING",
                "TRANSMISSION-MODE-DECLARATION",
                "TRANSMISSION-MODE-TRUE-TIMING",
                "CYCLIC-TIMING",
                "TIME-PERIOD",
                "VALUE",
            ]
        } else {
            &[
                "I-PDU-TIMING-SPECIFICATION",
                "CYCLIC-TIMING",
                "REPEATING-TIME",
                "VALUE",
            ]
        };
        let Some(e) = self.walk(pdu, steps)? else {
            return Ok(None);
        };
        let seconds = text(e).and_then(number).map(Num::as_f64);
        match seconds {
            // Seconds as written, in whole milliseconds (0.1 s is 100 ms, not 100.000…01).
            Some(s) if s > 0.0 && s < 3600.0 => {
                Ok(crate::decoder::integral((s * 1e6).round() / 1e3)
                    .or_else(|| crate::decoder::integral((s * 1e3).round())))
            }
            _ => {
                self.problem(
                    e,
                    format!(
                        "cycle time \"{}\" is not a number of seconds",
                        text(e).unwrap_or_default()
                    ),
                    "no cycle time",
                )?;
                Ok(None)
            }
        }
    }

    /// The signals a PDU maps.
    fn pdu_signals(&mut self, pdu: XmlNode<'a, 'input>) -> Result<Vec<Signal>, ParseError> {
        let lists: &[&str] = if self.version >= 4 {
            &["I-SIGNAL-TO-PDU-MAPPINGS", "I-SIGNAL-TO-I-PDU-MAPPINGS"]
        } else {
            &["SIGNAL-TO-PDU-MAPPINGS", "I-SIGNAL-TO-I-PDU-MAPPINGS"]
        };
        let mut out = Vec::new();
        for list in lists {
            for mapping in self.walk_all(pdu, &[list, "I-SIGNAL-TO-I-PDU-MAPPING"])? {
                if let Some(s) = self.signal(mapping)? {
                    out.push(s);
                }
            }
        }
        Ok(out)
    }

    fn signal(&mut self, mapping: XmlNode<'a, 'input>) -> Result<Option<Signal>, ParseError> {
        let i_signal_tag = if self.version >= 4 {
            "I-SIGNAL"
        } else {
            "SIGNAL"
        };
        // A mapping of a signal group maps no signal of its own.
        let Some(i_signal) = self.follow(mapping, i_signal_tag)? else {
            return Ok(None);
        };
        let system_signal = self.follow(i_signal, "SYSTEM-SIGNAL")?;
        if system_signal.is_some_and(|s| !is(s, "SYSTEM-SIGNAL")) {
            return Ok(None);
        }
        let name = short_name(i_signal).unwrap_or_default().to_string();
        let start = self.whole_at(mapping, &["START-POSITION"])?;
        let mut length = self.whole_at(i_signal, &["LENGTH"])?;
        if length.is_none() && self.version < 4 {
            if let Some(system) = system_signal {
                length = self.whole_at(system, &["LENGTH"])?;
            }
        }
        let (Some(start), Some(length)) = (start, length) else {
            self.problem(
                mapping,
                format!("signal {name} has no start position or length"),
                "signal left out",
            )?;
            return Ok(None);
        };
        let (Some(start), Some(length)) = (
            u32::try_from(start).ok().filter(|s| *s < 512),
            u32::try_from(length).ok().filter(|l| (1..=64).contains(l)),
        ) else {
            self.problem(
                mapping,
                format!("signal {name} needs a start below 512 and a length of 1 to 64 bits (it has {start} and {length})"),
                "signal left out",
            )?;
            return Ok(None);
        };
        let byte_order = match child(mapping, "PACKING-BYTE-ORDER").and_then(text) {
            Some("MOST-SIGNIFICANT-BYTE-FIRST") => ByteOrder::BigEndian,
            _ => ByteOrder::LittleEndian,
        };
        let mut s = plain_signal(
            name.clone(),
            (start, length, byte_order),
            Multiplexing::None,
            self.at(mapping),
        );
        let base_type = self.walk(
            i_signal,
            &[
                "NETWORK-REPRESENTATION-PROPS",
                "SW-DATA-DEF-PROPS-VARIANTS",
                "SW-DATA-DEF-PROPS-CONDITIONAL",
                "BASE-TYPE",
            ],
        )?;
        if let Some(base) = base_type {
            s.value_type = match child(base, "BASE-TYPE-ENCODING").and_then(text) {
                Some("2C" | "1C" | "SM") => ValueType::Integer { signed: true },
                Some("IEEE754") if length == 32 => ValueType::Float32,
                Some("IEEE754") if length == 64 => ValueType::Float64,
                Some("IEEE754") => {
                    self.problem(
                        base,
                        format!("signal {name} is an IEEE 754 float of {length} bits"),
                        "read as an unsigned integer",
                    )?;
                    s.value_type
                }
                _ => s.value_type,
            };
        }
        let mut minimum = None;
        let mut maximum = None;
        if let Some(system) = system_signal {
            s.comment = self.comment(system);
            let compu = if self.version >= 4 {
                self.walk(
                    system,
                    &[
                        "PHYSICAL-PROPS",
                        "SW-DATA-DEF-PROPS-VARIANTS",
                        "SW-DATA-DEF-PROPS-CONDITIONAL",
                        "COMPU-METHOD",
                    ],
                )?
            } else {
                self.walk(system, &["DATA-TYPE", "SW-DATA-DEF-PROPS", "COMPU-METHOD"])?
            };
            let mut unit = self
                .walk(
                    system,
                    &[
                        "PHYSICAL-PROPS",
                        "SW-DATA-DEF-PROPS-VARIANTS",
                        "SW-DATA-DEF-PROPS-CONDITIONAL",
                        "UNIT",
                        "DISPLAY-NAME",
                    ],
                )?
                .and_then(text);
            if let Some(c) = compu {
                if unit.is_none() {
                    unit = self.walk(c, &["UNIT", "DISPLAY-NAME"])?.and_then(text);
                }
                (minimum, maximum) = self.compu_method(c, &mut s)?;
            }
            s.unit = unit
                .filter(|u| *u != "NoUnit")
                .unwrap_or_default()
                .to_string();
        }
        crate::format::set_range(&mut s, minimum, maximum);
        let initial = if self.version >= 4 {
            match self.walk(
                i_signal,
                &["INIT-VALUE", "NUMERICAL-VALUE-SPECIFICATION", "VALUE"],
            )? {
                Some(v) => Some(v),
                None => self.walk(
                    i_signal,
                    &[
                        "INIT-VALUE",
                        "CONSTANT-REFERENCE",
                        "CONSTANT",
                        "VALUE-SPEC",
                        "NUMERICAL-VALUE-SPECIFICATION",
                        "VALUE",
                    ],
                )?,
            }
        } else {
            match system_signal {
                Some(system) => self.walk(system, &["INIT-VALUE", "VALUE"])?,
                None => None,
            }
        };
        if let Some(value) = initial.and_then(text).and_then(number) {
            s.attributes
                .push((attrs::START_VALUE.to_string(), AttrValue::Number(value)));
        }
        Ok(Some(s))
    }

    /// A compu method's scaling and value names onto `s`; the range its limits give.
    fn compu_method(
        &mut self,
        c: XmlNode<'a, 'input>,
        s: &mut Signal,
    ) -> Result<(Option<Num>, Option<Num>), ParseError> {
        let category = child(c, "CATEGORY").and_then(text);
        let scales = self.walk_all(
            c,
            &["COMPU-INTERNAL-TO-PHYS", "COMPU-SCALES", "COMPU-SCALE"],
        )?;
        let name = s.name.clone();
        let mut range = (None, None);
        let mut linear_seen = false;
        match category {
            Some("IDENTICAL") => return Ok(range),
            // Without a category, the scales say what they are (canmatrix writes none).
            None | Some("TEXTTABLE" | "LINEAR" | "SCALE_LINEAR_AND_TEXTTABLE" | "SCALE_LINEAR") => {
            }
            Some(other) => {
                self.warning(
                    c,
                    format!("signal {name}'s compu method is {other}: bywire reads IDENTICAL, LINEAR, SCALE_LINEAR, TEXTTABLE and SCALE_LINEAR_AND_TEXTTABLE"),
                    "read unscaled",
                )?;
                return Ok(range);
            }
        }
        // The physical value is a float from here on, as AUTOSAR's coefficients are.
        s.factor = Num::Float(1.0);
        s.offset = Num::Float(0.0);
        for scale in scales {
            let limit = |tag| child(scale, tag).and_then(text).and_then(number);
            let (low, high) = (limit("LOWER-LIMIT"), limit("UPPER-LIMIT"));
            let constant = self.walk(scale, &["COMPU-CONST", "VT"])?.and_then(text);
            if let Some(label) = constant {
                if category == Some("LINEAR") || category == Some("SCALE_LINEAR") {
                    continue;
                }
                let value = match (low.or(high), high.or(low)) {
                    (Some(a), Some(b)) if a == b => match a {
                        Num::Int(i) => Some(i),
                        Num::Float(f) => crate::decoder::integral(f),
                    },
                    _ => None,
                };
                match value {
                    Some(v) => s.value_descriptions.push((v, label.to_string())),
                    None => self.problem(
                        scale,
                        format!("signal {name}'s value name {label} is not for one whole value"),
                        "value name left out",
                    )?,
                }
                continue;
            }
            if category == Some("TEXTTABLE") {
                continue;
            }
            if linear_seen {
                self.warning(
                    scale,
                    format!("signal {name} is scaled piecewise: bywire keeps one linear segment"),
                    "the first segment kept",
                )?;
                continue;
            }
            linear_seen = true;
            let (factor, offset) = match self.walk(scale, &["COMPU-RATIONAL-COEFFS"])? {
                None => (1.0, 0.0),
                Some(coeffs) => {
                    let values = |tag| {
                        child(coeffs, tag)
                            .map(|n| {
                                children(n, "V")
                                    .map(|v| text(v).and_then(number).map(Num::as_f64))
                                    .collect::<Vec<_>>()
                            })
                            .unwrap_or_default()
                    };
                    match (
                        values("COMPU-NUMERATOR").as_slice(),
                        values("COMPU-DENOMINATOR").as_slice(),
                    ) {
                        ([Some(n0), Some(n1)], [Some(d)]) if *d != 0.0 => (n1 / d, n0 / d),
                        (n, d) => {
                            self.problem(
                                coeffs,
                                format!(
                                    "signal {name}'s linear scaling needs 2 numerator values and 1 \
                                     non-zero denominator value (it has {} and {})",
                                    n.len(),
                                    d.len()
                                ),
                                "read unscaled",
                            )?;
                            (1.0, 0.0)
                        }
                    }
                }
            };
            s.factor = Num::Float(factor);
            s.offset = Num::Float(offset);
            let scaled = |raw: Option<Num>| raw.map(|r| Num::Float(r.as_f64() * factor + offset));
            range = match (low, high) {
                (Some(l), Some(h)) if l.as_f64() > h.as_f64() => (None, None),
                (l, h) => (scaled(l), scaled(h)),
            };
        }
        Ok(range)
    }

    /// The E2E protection a PDU's signal group declares through an E2E transformer.
    fn signal_group_e2e(&mut self, pdu: XmlNode<'a, 'input>) -> Result<Option<E2e>, ParseError> {
        let groups = self.walk_all(
            pdu,
            &[
                "I-SIGNAL-TO-PDU-MAPPINGS",
                "I-SIGNAL-TO-I-PDU-MAPPING",
                "I-SIGNAL-GROUP",
            ],
        )?;
        let Some(group) = groups.last().copied() else {
            return Ok(None);
        };
        let Some(props) = self.walk(
            group,
            &[
                "TRANSFORMATION-I-SIGNAL-PROPSS",
                "END-TO-END-TRANSFORMATION-I-SIGNAL-PROPS",
                "END-TO-END-TRANSFORMATION-I-SIGNAL-PROPS-VARIANTS",
                "END-TO-END-TRANSFORMATION-I-SIGNAL-PROPS-CONDITIONAL",
            ],
        )?
        else {
            return Ok(None);
        };
        let description = self.walk(
            props,
            &[
                "TRANSFORMER",
                "TRANSFORMATION-DESCRIPTIONS",
                "END-TO-END-TRANSFORMATION-DESCRIPTION",
            ],
        )?;
        let profile = description
            .and_then(|d| child(d, "PROFILE-NAME"))
            .and_then(text)
            .unwrap_or_default()
            .to_string();
        let data_ids = self.data_ids(props)?;
        let (crc_offset, counter_offset) = match description {
            Some(d) => self.offsets(d)?,
            None => (None, None),
        };
        Ok(Some(E2e {
            profile,
            data_ids,
            crc_offset,
            counter_offset,
            data_id_mode: description.and_then(data_id_mode),
            at: self.at(props),
        }))
    }

    fn data_ids(&mut self, n: XmlNode<'a, 'input>) -> Result<Vec<i128>, ParseError> {
        let mut ids = Vec::new();
        for e in self.walk_all(n, &["DATA-IDS", "DATA-ID"])? {
            match text(e).and_then(whole) {
                Some(id) => ids.push(id),
                None => self.problem(e, "a data ID that is not a whole number", "left out")?,
            }
        }
        Ok(ids)
    }

    fn offsets(
        &mut self,
        n: XmlNode<'a, 'input>,
    ) -> Result<(Option<u32>, Option<u32>), ParseError> {
        let bits = |v: Option<i128>| v.and_then(|v| u32::try_from(v).ok());
        Ok((
            bits(self.whole_at(n, &["CRC-OFFSET"])?),
            bits(self.whole_at(n, &["COUNTER-OFFSET"])?),
        ))
    }

    /// E2E protection sets: each protection's profile onto the PDUs it protects.
    fn protection_sets(
        &mut self,
        root: XmlNode<'a, 'input>,
        units: &mut [Unit],
    ) -> Result<(), ParseError> {
        let protections: Vec<XmlNode<'a, 'input>> = root
            .descendants()
            .filter(|n| is(*n, "END-TO-END-PROTECTION"))
            .collect();
        for protection in protections {
            let Some(profile) = child(protection, "END-TO-END-PROFILE") else {
                continue;
            };
            let data_ids = self.data_ids(profile)?;
            let (crc_offset, counter_offset) = self.offsets(profile)?;
            let e2e = E2e {
                profile: child(profile, "CATEGORY")
                    .and_then(text)
                    .unwrap_or_default()
                    .to_string(),
                data_ids,
                crc_offset,
                counter_offset,
                data_id_mode: data_id_mode(profile),
                at: self.at(protection),
            };
            let pdus = self.walk_all(
                protection,
                &[
                    "END-TO-END-PROTECTION-I-SIGNAL-I-PDUS",
                    "END-TO-END-PROTECTION-I-SIGNAL-I-PDU",
                    "I-SIGNAL-I-PDU",
                ],
            )?;
            for pdu in pdus {
                let path = self.path(pdu);
                for unit in units.iter_mut() {
                    if unit.pdu_paths.contains(&path) && !unit.message.signals.is_empty() {
                        unit.e2e = Some(e2e.clone());
                    }
                }
            }
        }
        Ok(())
    }

    /// An ECU instance's PDU groups: it sends those going out and receives those coming in.
    fn senders_and_receivers(
        &mut self,
        ecu: XmlNode<'a, 'input>,
        units: &mut [Unit],
    ) -> Result<(), ParseError> {
        let ecu_name = short_name(ecu).unwrap_or_default().to_string();
        let (groups, pdus): (&[&str], &[&str]) = if self.version >= 4 {
            (
                &[
                    "ASSOCIATED-COM-I-PDU-GROUP-REFS",
                    "ASSOCIATED-COM-I-PDU-GROUP",
                ],
                &[
                    "I-SIGNAL-I-PDUS",
                    "I-SIGNAL-I-PDU-REF-CONDITIONAL",
                    "I-SIGNAL-I-PDU",
                ],
            )
        } else {
            (
                &["ASSOCIATED-I-PDU-GROUP-REFS", "ASSOCIATED-I-PDU-GROUP"],
                &["I-PDU-REFS", "I-PDU"],
            )
        };
        for group in self.walk_all(ecu, groups)? {
            let direction = child(group, "COMMUNICATION-DIRECTION").and_then(text);
            let paths: Vec<String> = self
                .walk_all(group, pdus)?
                .into_iter()
                .map(|p| self.path(p))
                .collect();
            for path in paths {
                match direction {
                    Some("IN") => receive(units, &path, &ecu_name),
                    Some("OUT") => send(units, &path, &ecu_name),
                    _ => {}
                }
            }
        }
        Ok(())
    }

    /// Network-management nodes: the ECU of each node's controller sends its transmitted PDUs
    /// and receives its received ones.
    fn network_management(
        &mut self,
        root: XmlNode<'a, 'input>,
        units: &mut [Unit],
    ) -> Result<(), ParseError> {
        if self.version < 4 {
            return Ok(());
        }
        let nodes: Vec<XmlNode<'a, 'input>> = root
            .descendants()
            .filter(|n| is(*n, "CAN-NM-NODE"))
            .collect();
        for node in nodes {
            // The controller sits inside its ECU instance.
            let Some(controller) = self.follow(node, "CONTROLLER")? else {
                continue;
            };
            let Some(ecu) = controller.ancestors().find(|a| is(*a, "ECU-INSTANCE")) else {
                continue;
            };
            let ecu_name = short_name(ecu).unwrap_or_default().to_string();
            for (list, tag, sends) in [
                ("RX-NM-PDU-REFS", "RX-NM-PDU", false),
                ("TX-NM-PDU-REFS", "TX-NM-PDU", true),
            ] {
                for pdu in self.walk_all(node, &[list, tag])? {
                    let path = self.path(pdu);
                    if sends {
                        send(units, &path, &ecu_name);
                    } else {
                        receive(units, &path, &ecu_name);
                    }
                }
            }
        }
        Ok(())
    }

    /// An E2E protection as the counter and checksum attributes, when bywire computes its
    /// profile; a warning when it does not.
    fn declare_e2e(&mut self, message: &mut Message, e2e: &E2e) -> Result<(), ParseError> {
        // Profile 1 with both data ID bytes (its default), the CRC checked against the
        // autosar-e2e package; other profiles and data ID modes are named, not guessed.
        let profile = e2e.profile.to_ascii_uppercase().replace(['-', ' '], "_");
        let both_bytes = e2e
            .data_id_mode
            .as_deref()
            .is_none_or(|m| m == "ALL-16-BIT");
        let crc8 = matches!(
            profile.as_str(),
            "PROFILE_01" | "PROFILE01" | "PROFILE1" | "P01"
        ) && both_bytes;
        let name = message.name.clone();
        let find = |m: &Message, bit: u32, length: u32| {
            m.signals.iter().position(|s| {
                s.byte_order == ByteOrder::LittleEndian && s.start_bit == bit && s.length == length
            })
        };
        let counter = find(message, e2e.counter_offset.unwrap_or(8), 4);
        let checksum = find(message, e2e.crc_offset.unwrap_or(0), 8);
        let usable = crc8 && e2e.data_ids.len() == 1 && counter.is_some() && checksum.is_some();
        if !usable {
            let why = if crc8 {
                "it needs one data ID and a 4-bit counter and an 8-bit CRC at their offsets"
            } else {
                "bywire computes profile 1 with both data ID bytes (ALL-16-BIT)"
            };
            self.report.add(
                Severity::Warning,
                e2e.at,
                format!(
                    "message {name} is protected by E2E {} with data IDs {:?}: {why}",
                    e2e.profile, e2e.data_ids
                ),
                "its counter and CRC are decoded but not checked",
            )?;
            return Ok(());
        }
        let int = |v: i128| AttrValue::Number(Num::Int(v));
        if let Some(s) = counter.and_then(|i| message.signals.get_mut(i)) {
            s.attributes.push(("RollingCounter".to_string(), int(1)));
        }
        if let Some(s) = checksum.and_then(|i| message.signals.get_mut(i)) {
            s.attributes.push((
                "ChecksumAlgorithm".to_string(),
                AttrValue::Str("e2e_profile1".to_string()),
            ));
            if let Some(id) = e2e.data_ids.first() {
                s.attributes.push(("ChecksumDataId".to_string(), int(*id)));
            }
        }
        Ok(())
    }
}

/// An E2E profile's or description's data ID mode.
fn data_id_mode(n: XmlNode<'_, '_>) -> Option<String> {
    child(n, "DATA-ID-MODE").and_then(text).map(str::to_string)
}

/// An ECUC container's parameter value, by the last part of its definition's path.
fn parameter<'a>(n: XmlNode<'a, '_>, name: &str) -> Option<&'a str> {
    child(n, "PARAMETER-VALUES")?
        .children()
        .filter(XmlNode::is_element)
        .find(|p| {
            child(*p, "DEFINITION-REF")
                .and_then(text)
                .is_some_and(|d| d.rsplit('/').next() == Some(name))
        })
        .and_then(|p| child(p, "VALUE"))
        .and_then(text)
}

/// An ECUC container's references of one definition: the paths they name.
fn references<'a>(n: XmlNode<'a, '_>, name: &'a str) -> impl Iterator<Item = &'a str> + 'a {
    child(n, "REFERENCE-VALUES")
        .into_iter()
        .flat_map(|r| r.children().filter(XmlNode::is_element))
        .filter(move |r| {
            child(*r, "DEFINITION-REF")
                .and_then(text)
                .is_some_and(|d| d.rsplit('/').next() == Some(name))
        })
        .filter_map(|r| child(r, "VALUE-REF").and_then(text))
}

fn reference<'a>(n: XmlNode<'a, '_>, name: &'a str) -> Option<&'a str> {
    references(n, name).next()
}

/// Every message that carries the PDU at `path`.
fn carrying<'u>(units: &'u mut [Unit], path: &'u str) -> impl Iterator<Item = &'u mut Unit> {
    units
        .iter_mut()
        .filter(move |u| u.pdu_paths.iter().any(|p| p == path))
}

fn send(units: &mut [Unit], path: &str, ecu: &str) {
    for unit in carrying(units, path) {
        let m = &mut unit.message;
        if m.transmitter == NO_NODE {
            m.transmitter = ecu.to_string();
        } else if m.transmitter != ecu && !m.senders.iter().any(|s| s == ecu) {
            m.senders.push(ecu.to_string());
        }
    }
}

fn receive(units: &mut [Unit], path: &str, ecu: &str) {
    for unit in carrying(units, path) {
        for s in &mut unit.message.signals {
            if s.receivers.iter().all(|r| r == NO_NODE) {
                s.receivers.clear();
            }
            if !s.receivers.iter().any(|r| r == ecu) {
                s.receivers.push(ecu.to_string());
            }
        }
    }
}

/// Define every attribute the reader gave a value.
fn define_attributes(db: &mut Database) {
    attrs::define_used(db);
    let int = |scope, name: &str, max: i128| AttrDef {
        scope,
        name: name.to_string(),
        kind: AttrType::Int(Num::Int(0), Num::Int(max)),
        default: None,
    };
    let string = |scope, name: &str| AttrDef {
        scope,
        name: name.to_string(),
        kind: AttrType::Str,
        default: Some(AttrValue::Str(String::new())),
    };
    let extra = [
        string(AttrScope::Network, "DBName"),
        string(AttrScope::Message, BUS_NAME),
        int(AttrScope::Signal, "RollingCounter", 1),
        string(AttrScope::Signal, "ChecksumAlgorithm"),
        int(AttrScope::Signal, "ChecksumDataId", 65535),
        int(AttrScope::Message, "SecOCDataId", 65535),
        int(AttrScope::Message, "SecOCFreshnessValueLength", 64),
        int(AttrScope::Message, "SecOCFreshnessValueTxLength", 64),
        int(AttrScope::Message, "SecOCAuthInfoTxLength", 128),
        int(AttrScope::Message, "SecOCAuthenticPduLength", 64),
    ];
    let defs: Vec<AttrDef> = extra
        .into_iter()
        .filter(|d| attrs::used(db, &d.name))
        .collect();
    db.attribute_defs.extend(defs);
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    #[test]
    fn numbers_read_as_autosar_writes_them() {
        assert_eq!(number("0x1F"), Some(Num::Int(31)));
        assert_eq!(number("017"), Some(Num::Int(15)));
        assert_eq!(number("0b101"), Some(Num::Int(5)));
        assert_eq!(number("-12"), Some(Num::Int(-12)));
        assert_eq!(number("true"), Some(Num::Int(1)));
        assert_eq!(number("0.1"), Some(Num::Float(0.1)));
        assert_eq!(number("1e3"), Some(Num::Float(1000.0)));
        assert_eq!(number("0"), Some(Num::Int(0)));
        assert_eq!(number("zero"), None);
        assert_eq!(whole("123.0"), Some(123));
        assert_eq!(whole("1.5"), None);
    }
}
