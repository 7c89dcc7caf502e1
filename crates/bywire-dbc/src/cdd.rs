//! CANdela diagnostic descriptions (CDD): the data identifiers (DIDs) an ECU answers with, read
//! into the one model as cantools reads them, one message per DID (its identifier as `id`, its
//! data record's bytes as `size`), one signal per data object, so a DID's record decodes and
//! encodes with the codec every frame uses.
//!
//! The file's `DATATYPES` give each data object its bit length, byte order, scaling (`COMP`),
//! unit and value names (`TEXTMAP`); each `DIAGINST` of the ECU's variant is a DID, its
//! `STATICVALUE` the identifier, its data objects (directly, in a union's structure, in a
//! structure, or in the `DIDS` library its `DIDDATAREF` names) laid one after another from bit
//! 0. A field's offset becomes DBC's start bit as cantools maps it.

use std::collections::HashMap;

use roxmltree::Node as XmlNode;

use crate::format::{plain_signal, LineIndex, Report, NO_NODE};
use crate::model::*;
use crate::parser::{Diagnostic, Mode, ParseError, Severity};
use crate::xml::{child, children};

/// Elements a file may hold before it is refused.
const MAX_NODES: u32 = 20_000_000;

/// A data type of the file.
struct DataType {
    bits: u32,
    /// Wider than the 64 bits a signal holds (text, long byte strings): its place is kept, its
    /// value not read.
    too_wide: bool,
    byte_order: ByteOrder,
    value_type: ValueType,
    unit: String,
    factor: Num,
    offset: Num,
    names: Vec<(i128, String)>,
}

/// Read CDD text.
pub(crate) fn read(text: &str, mode: Mode) -> Result<(Database, Vec<Diagnostic>), ParseError> {
    // CANdela files name their DTD.
    let lines = LineIndex::new(text);
    let doc = crate::xml::parse(text, true, MAX_NODES)?;
    let mut reader = Reader {
        lines: &lines,
        report: Report::new(mode),
    };
    let db = reader.database(doc.root_element())?;
    reader.report.finish(db)
}

/// The elements at `path` below `n` (each step all children of that name).
fn all<'a, 'input>(n: XmlNode<'a, 'input>, path: &[&'a str]) -> Vec<XmlNode<'a, 'input>> {
    let mut here = vec![n];
    for step in path {
        here = here.into_iter().flat_map(|h| children(h, step)).collect();
    }
    here
}

/// The text of the first `TUV` of `n`'s `tag` child.
fn first_tuv(n: XmlNode<'_, '_>, tag: &str) -> Option<String> {
    let tuv = child(child(n, tag)?, "TUV")?;
    Some(
        tuv.descendants()
            .filter(XmlNode::is_text)
            .filter_map(|d| d.text())
            .collect::<String>(),
    )
}

struct Reader<'a, 'input> {
    lines: &'a LineIndex<'input>,
    report: Report,
}

impl<'input> Reader<'_, 'input> {
    fn at(&self, n: XmlNode<'_, 'input>) -> Position {
        self.lines.position(n.range().start)
    }

    fn problem(
        &mut self,
        n: XmlNode<'_, 'input>,
        severity: Severity,
        message: impl Into<String>,
        resolution: &str,
    ) -> Result<(), ParseError> {
        let at = self.at(n);
        self.report.add(severity, at, message, resolution)
    }

    fn database(&mut self, root: XmlNode<'_, 'input>) -> Result<Database, ParseError> {
        let Some(ecu_doc) = child(root, "ECUDOC") else {
            return Err(Report::fatal(
                self.at(root),
                format!(
                    "the root element {} holds no ECUDOC: not a CANdela file",
                    root.tag_name().name()
                ),
            ));
        };
        let types = self.data_types(ecu_doc)?;
        let library: HashMap<&str, XmlNode<'_, 'input>> = all(ecu_doc, &["DIDS", "DID"])
            .into_iter()
            .filter_map(|d| Some((d.attribute("id")?, d)))
            .collect();
        let Some(var) = child(ecu_doc, "ECU").and_then(|ecu| child(ecu, "VAR")) else {
            return Err(Report::fatal(
                self.at(ecu_doc),
                "the ECUDOC has no ECU with a VAR (variant)",
            ));
        };
        let mut db = Database::default();
        for instance in all(var, &["DIAGCLASS", "DIAGINST"]) {
            if let Some(message) = self.did(instance, &types, &library)? {
                db.messages.push(message);
            }
        }
        Ok(db)
    }

    fn data_types(
        &mut self,
        ecu_doc: XmlNode<'_, 'input>,
    ) -> Result<HashMap<String, DataType>, ParseError> {
        let mut types = HashMap::new();
        for t in all(ecu_doc, &["DATATYPES"])
            .into_iter()
            .flat_map(|d| d.children().filter(XmlNode::is_element))
        {
            let (Some(id), Some(c)) = (t.attribute("id"), child(t, "CVALUETYPE")) else {
                // Structures and the like: no value of their own.
                continue;
            };
            let name = first_tuv(t, "NAME").unwrap_or_default();
            let bits = c.attribute("bl").and_then(|b| b.parse::<u32>().ok());
            let Some(bits) = bits.filter(|b| (1..=512).contains(b)) else {
                self.problem(
                    c,
                    Severity::Error,
                    format!("data type {name} needs a bit length (bl) of 1 to 512"),
                    "data type left out",
                )?;
                continue;
            };
            let too_wide = bits > 64;
            if too_wide {
                self.problem(
                    c,
                    Severity::Warning,
                    format!(
                        "data type {name} is {bits} bits, wider than a signal's 64: its fields keep \
                         their place in their DIDs, their values are not read"
                    ),
                    "fields left out",
                )?;
            }
            let byte_order = match c.attribute("bo") {
                Some("12") => ByteOrder::LittleEndian,
                Some("21") | None => ByteOrder::BigEndian,
                Some(other) => {
                    self.problem(
                        c,
                        Severity::Error,
                        format!("data type {name}'s byte order code {other} is neither 12 nor 21"),
                        "read as big-endian (21)",
                    )?;
                    ByteOrder::BigEndian
                }
            };
            let value_type = match (c.attribute("enc"), bits) {
                (Some("sgn" | "s" | "2c"), _) => ValueType::Integer { signed: true },
                (Some("flt"), 32) => ValueType::Float32,
                (Some("flt" | "dbl"), 64) => ValueType::Float64,
                (Some("bcd" | "asc" | "utf"), _) if !too_wide => {
                    self.problem(
                        c,
                        Severity::Warning,
                        format!(
                            "data type {name} is encoded as {}: its bits are read as an unsigned number",
                            c.attribute("enc").unwrap_or_default()
                        ),
                        "read as unsigned",
                    )?;
                    ValueType::Integer { signed: false }
                }
                _ => ValueType::Integer { signed: false },
            };
            let (factor, offset) = match child(t, "COMP") {
                Some(comp) => {
                    let number = |key| {
                        comp.attribute(key)
                            .and_then(|v| crate::parser::parse_num(v.trim()))
                    };
                    match (number("f"), number("o")) {
                        (Some(f), Some(o)) => (f, o),
                        _ => {
                            self.problem(
                                comp,
                                Severity::Error,
                                format!("data type {name}'s scaling (f, o) is not two numbers"),
                                "read unscaled",
                            )?;
                            (Num::Int(1), Num::Int(0))
                        }
                    }
                }
                None => (Num::Int(1), Num::Int(0)),
            };
            let mut names = Vec::new();
            for map in children(t, "TEXTMAP") {
                let bound = |key| {
                    map.attribute(key)
                        .map(|v| v.trim_matches(['(', ')']))
                        .and_then(|v| v.parse::<i128>().ok())
                };
                match (bound("s"), bound("e"), first_tuv(map, "TEXT")) {
                    (Some(s), Some(e), Some(text)) if s == e => names.push((s, text)),
                    // A range of values under one name: DBC names single values.
                    (Some(_), Some(_), Some(_)) => {}
                    _ => self.problem(
                        map,
                        Severity::Error,
                        format!("a value name of data type {name} lacks its bounds or text"),
                        "value name left out",
                    )?,
                }
            }
            let unit = child(t, "PVALUETYPE")
                .and_then(|p| child(p, "UNIT"))
                .and_then(|u| u.text())
                .unwrap_or_default()
                .to_string();
            types.insert(
                id.to_string(),
                DataType {
                    bits,
                    too_wide,
                    byte_order,
                    value_type,
                    unit,
                    factor,
                    offset,
                    names,
                },
            );
        }
        Ok(types)
    }

    /// One DID: its data objects laid out from bit 0, in cantools' order.
    fn did(
        &mut self,
        instance: XmlNode<'_, 'input>,
        types: &HashMap<String, DataType>,
        library: &HashMap<&str, XmlNode<'_, 'input>>,
    ) -> Result<Option<Message>, ParseError> {
        let name = child(instance, "QUAL")
            .and_then(|q| q.text())
            .unwrap_or_default()
            .to_string();
        let identifier = child(instance, "STATICVALUE")
            .and_then(|s| s.attribute("v"))
            .and_then(|v| v.trim().parse::<u32>().ok());
        let Some(id) = identifier.filter(|id| *id <= 0xFFFF) else {
            self.problem(
                instance,
                Severity::Error,
                format!("DID {name} has no identifier (STATICVALUE v) of 0 to 65535"),
                "DID left out",
            )?;
            return Ok(None);
        };
        let mut objects = all(instance, &["SIMPLECOMPCONT", "DATAOBJ"]);
        objects.extend(all(
            instance,
            &["SIMPLECOMPCONT", "UNION", "STRUCT", "DATAOBJ"],
        ));
        let references = all(instance, &["SIMPLECOMPCONT", "DIDDATAREF"]);
        // A structure beside a DID data reference is not part of the record (an I/O control's
        // enable mask).
        if references.is_empty() {
            objects.extend(all(instance, &["SIMPLECOMPCONT", "STRUCT", "DATAOBJ"]));
        }
        for r in references {
            let target = r.attribute("didRef").and_then(|id| library.get(id));
            match target {
                Some(did) => objects.extend(all(*did, &["STRUCTURE", "DATAOBJ"])),
                None => self.problem(
                    r,
                    Severity::Error,
                    format!("DID {name} refers to data that the DIDS library lacks"),
                    "reference skipped",
                )?,
            }
        }
        let mut offset: u32 = 0;
        let mut signals = Vec::new();
        for object in objects {
            let field = child(object, "QUAL")
                .and_then(|q| q.text())
                .unwrap_or_default()
                .to_string();
            let Some(t) = object.attribute("dtref").and_then(|r| types.get(r)) else {
                self.problem(
                    object,
                    Severity::Error,
                    format!("data {field} of DID {name} names no data type with a value"),
                    "the DID left out (its later fields' places are unknown)",
                )?;
                return Ok(None);
            };
            if offset + t.bits > 512 {
                self.problem(
                    object,
                    Severity::Error,
                    format!("DID {name} is longer than 64 bytes at data {field}"),
                    "its later data left out",
                )?;
                break;
            }
            if t.too_wide {
                offset += t.bits;
                continue;
            }
            let start = match t.byte_order {
                ByteOrder::BigEndian => 8 * (offset / 8) + (offset % 8 + t.bits - 1).min(7),
                ByteOrder::LittleEndian => offset,
            };
            let mut s = plain_signal(
                field,
                (start, t.bits, t.byte_order),
                Multiplexing::None,
                self.at(object),
            );
            s.value_type = t.value_type;
            s.factor = t.factor;
            s.offset = t.offset;
            s.unit = t.unit.clone();
            s.value_descriptions = t.names.clone();
            signals.push(s);
            offset += t.bits;
        }
        Ok(Some(Message {
            id,
            extended: false,
            name,
            size: offset.div_ceil(8),
            transmitter: NO_NODE.to_string(),
            senders: Vec::new(),
            signals,
            comment: None,
            attributes: Vec::new(),
            position: self.at(instance),
        }))
    }
}
