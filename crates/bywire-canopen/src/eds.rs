//! EDS and DCF files (CiA 306): read into an [`ObjectDictionary`] with diagnostics that name
//! the line, and written back out.
//!
//! The INI reader is our own rather than an INI crate's because every diagnostic must carry
//! its line, and vendor files need leniency INI crates do not have (keys and section names in
//! any case, `;` comments after values, a byte-order mark, CRLF, duplicate keys).
//!
//! Quirks handled, each with a diagnostic where something was guessed: `$NODEID` in values
//! (`$NODEID+0x180`, `0x180+$NODEID`), octal and hex numbers, a missing `ObjectType` (VAR), a
//! missing `DataType` on sub-objects of an array (the array's), `CompactSubObj` arrays (names
//! from `[xxxxName]`), `SubNumber` disagreeing with the sub-objects present, objects listed
//! but not described (and described but not listed), empty or unparsable default values,
//! `ParameterValue` from a DCF overriding the default, `DEFTYPE` sections (skipped).

use alloc::collections::BTreeMap;
use alloc::format;
use alloc::string::{String, ToString};
use alloc::vec::Vec;
use core::fmt;

use crate::od::{Access, DataType, Entry, Number, ObjectDictionary, ObjectKind};

/// How bad a diagnostic is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Severity {
    /// Something was guessed or ignored; the dictionary is still as the file meant.
    Warning,
    /// An object (or part of one) could not be read and was left out.
    Error,
}

/// One problem found in a file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Diagnostic {
    /// The line (from 1) where it was found; 0 for the file as a whole.
    pub line: usize,
    /// How bad.
    pub severity: Severity,
    /// What, in words.
    pub message: String,
}

impl fmt::Display for Diagnostic {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let severity = match self.severity {
            Severity::Warning => "warning",
            Severity::Error => "error",
        };
        write!(f, "line {}: {severity}: {}", self.line, self.message)
    }
}

/// Device information from `[DeviceInfo]` and, in a DCF, `[DeviceComissioning]`.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct DeviceInfo {
    /// Vendor name.
    pub vendor_name: String,
    /// Vendor number.
    pub vendor_number: u32,
    /// Product name.
    pub product_name: String,
    /// Product number.
    pub product_number: u32,
    /// Revision number.
    pub revision_number: u32,
    /// Supported bit rates, kbit/s.
    pub bitrates: Vec<u32>,
    /// Node ID from a DCF.
    pub node_id: Option<u8>,
    /// Bit rate from a DCF, kbit/s.
    pub bitrate: Option<u32>,
}

/// What a file holds.
#[derive(Debug, Clone)]
pub struct Eds {
    /// The objects.
    pub dictionary: ObjectDictionary,
    /// The device.
    pub info: DeviceInfo,
    /// Everything guessed, ignored or left out, in line order.
    pub diagnostics: Vec<Diagnostic>,
}

/// A file that could not be read at all.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("line {line}: {message}")]
pub struct EdsError {
    /// The line (from 1).
    pub line: usize,
    /// What.
    pub message: String,
}

#[derive(Debug, Clone, Default)]
struct Section {
    line: usize,
    /// Lower-cased key → (value, line).
    keys: BTreeMap<String, (String, usize)>,
}

impl Section {
    fn get(&self, key: &str) -> Option<(&str, usize)> {
        self.keys
            .get(&key.to_ascii_lowercase())
            .map(|(value, line)| (value.as_str(), *line))
    }
}

struct Reader {
    sections: BTreeMap<String, Section>,
    diagnostics: Vec<Diagnostic>,
    node_id: Option<u8>,
}

impl Reader {
    fn warn(&mut self, line: usize, message: String) {
        self.diagnostics.push(Diagnostic {
            line,
            severity: Severity::Warning,
            message,
        });
    }

    fn error(&mut self, line: usize, message: String) {
        self.diagnostics.push(Diagnostic {
            line,
            severity: Severity::Error,
            message,
        });
    }
}

/// Split the file into sections; section names are upper-cased (`1a00sub1` → `1A00SUB1`).
fn sections(text: &str, diagnostics: &mut Vec<Diagnostic>) -> BTreeMap<String, Section> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut sections: BTreeMap<String, Section> = BTreeMap::new();
    let mut current: Option<String> = None;
    for (number, raw) in text.lines().enumerate() {
        let line = number + 1;
        let trimmed = raw.trim();
        if trimmed.is_empty() || trimmed.starts_with(';') || trimmed.starts_with('#') {
            continue;
        }
        if let Some(rest) = trimmed.strip_prefix('[') {
            let Some(name) = rest.split(']').next().filter(|_| rest.contains(']')) else {
                diagnostics.push(Diagnostic {
                    line,
                    severity: Severity::Error,
                    message: format!("section header without ']': {trimmed}"),
                });
                current = None;
                continue;
            };
            let name = name.trim().to_ascii_uppercase();
            if sections.contains_key(&name) {
                diagnostics.push(Diagnostic {
                    line,
                    severity: Severity::Warning,
                    message: format!("section [{name}] appears again; its keys are merged"),
                });
            }
            sections.entry(name.clone()).or_insert_with(|| Section {
                line,
                keys: BTreeMap::new(),
            });
            current = Some(name);
            continue;
        }
        let Some((key, value)) = trimmed.split_once('=') else {
            diagnostics.push(Diagnostic {
                line,
                severity: Severity::Warning,
                message: format!("not 'key=value', ignored: {trimmed}"),
            });
            continue;
        };
        let Some(section) = current.as_ref().and_then(|name| sections.get_mut(name)) else {
            diagnostics.push(Diagnostic {
                line,
                severity: Severity::Warning,
                message: format!("'{}' outside any section, ignored", key.trim()),
            });
            continue;
        };
        // Inline comments: a ';' after the value (python-canopen's reader does the same).
        let value = value.split(';').next().unwrap_or("").trim().to_string();
        let key = key.trim().to_ascii_lowercase();
        if section.keys.insert(key.clone(), (value, line)).is_some() {
            diagnostics.push(Diagnostic {
                line,
                severity: Severity::Warning,
                message: format!("'{key}' given twice; the last one counts"),
            });
        }
    }
    sections
}

/// Read an integer as CiA 306 writes them: decimal, `0x` hex, leading-`0` octal, and
/// `$NODEID` sums.
fn number(text: &str, node_id: Option<u8>) -> Result<i128, String> {
    let text = text.trim();
    if text.to_ascii_uppercase().contains("$NODEID") {
        let node =
            node_id.ok_or_else(|| format!("'{text}' uses $NODEID but no node ID is known"))?;
        let mut sum = 0i128;
        for term in text.split('+') {
            let term = term.trim();
            sum += if term.eq_ignore_ascii_case("$NODEID") {
                i128::from(node)
            } else {
                number(term, None)?
            };
        }
        return Ok(sum);
    }
    let (negative, digits) = match text.strip_prefix('-') {
        Some(rest) => (true, rest),
        None => (false, text),
    };
    let value = if let Some(hex) = digits
        .strip_prefix("0x")
        .or_else(|| digits.strip_prefix("0X"))
    {
        i128::from_str_radix(hex, 16).ok()
    } else if digits.len() > 1
        && digits.starts_with('0')
        && digits.bytes().all(|b| (b'0'..=b'7').contains(&b))
    {
        i128::from_str_radix(digits, 8).ok()
    } else {
        digits.parse::<i128>().ok()
    };
    let value = value.ok_or_else(|| format!("'{text}' is not a number"))?;
    Ok(if negative { -value } else { value })
}

/// Read an EDS or DCF file's bytes: UTF-8, or Windows-1252 (Latin-1) as many vendors' tools
/// write them — said in a warning. Otherwise as [`parse`].
pub fn parse_bytes(bytes: &[u8], node_id: Option<u8>) -> Result<Eds, EdsError> {
    match core::str::from_utf8(bytes) {
        Ok(text) => parse(text, node_id),
        Err(e) => {
            let text: String = bywire_core::text::cp1252_chars(bytes).collect();
            let mut eds = parse(&text, node_id)?;
            let line = bytes.get(..e.valid_up_to()).map_or(0, |before| {
                before.iter().filter(|&&b| b == b'\n').count() + 1
            });
            eds.diagnostics.insert(
                0,
                Diagnostic {
                    line,
                    severity: Severity::Warning,
                    message: "not UTF-8: read as Windows-1252 (Latin-1)".into(),
                },
            );
            Ok(eds)
        }
    }
}

/// Read an EDS or DCF file. `node_id` resolves `$NODEID` (a DCF's own node ID is used when it
/// is `None`). Objects that cannot be read are left out with an error diagnostic; the result
/// is an error only when the file has no object at all.
pub fn parse(text: &str, node_id: Option<u8>) -> Result<Eds, EdsError> {
    let mut diagnostics = Vec::new();
    let sections = sections(text, &mut diagnostics);
    let mut reader = Reader {
        sections,
        diagnostics,
        node_id,
    };
    let info = device_info(&mut reader);
    if reader.node_id.is_none() {
        reader.node_id = info.node_id;
    }
    let mut od = ObjectDictionary::new();
    let indices: Vec<(u16, usize)> = reader
        .sections
        .iter()
        .filter(|(name, _)| name.len() == 4)
        .filter_map(|(name, section)| {
            u16::from_str_radix(name, 16)
                .ok()
                .map(|index| (index, section.line))
        })
        .collect();
    if indices.is_empty() {
        return Err(EdsError {
            line: 1,
            message: "no object sections ([1000], [1018], ...): not an EDS/DCF file".to_string(),
        });
    }
    for (index, line) in &indices {
        read_object(&mut reader, &mut od, *index, *line);
    }
    check_lists(&mut reader, &indices);
    reader.diagnostics.sort_by_key(|d| d.line);
    Ok(Eds {
        dictionary: od,
        info,
        diagnostics: reader.diagnostics,
    })
}

fn device_info(reader: &mut Reader) -> DeviceInfo {
    let mut info = DeviceInfo::default();
    let Some(section) = reader.sections.get("DEVICEINFO").cloned() else {
        reader.warn(
            0,
            "no [DeviceInfo] section (CiA 306 requires one)".to_string(),
        );
        return info;
    };
    let text = |key: &str| {
        section
            .get(key)
            .map(|(v, _)| v.to_string())
            .unwrap_or_default()
    };
    let int = |reader: &mut Reader, key: &str| match section.get(key) {
        Some((value, line)) => number(value, None).map_or_else(
            |problem| {
                reader.warn(line, format!("[DeviceInfo] {key}: {problem}"));
                0
            },
            |v| u32::try_from(v).unwrap_or(0),
        ),
        None => 0,
    };
    info.vendor_name = text("VendorName");
    info.product_name = text("ProductName");
    info.vendor_number = int(reader, "VendorNumber");
    info.product_number = int(reader, "ProductNumber");
    info.revision_number = int(reader, "RevisionNumber");
    for rate in [10, 20, 50, 125, 250, 500, 800, 1000] {
        if section
            .get(&format!("BaudRate_{rate}"))
            .is_some_and(|(v, _)| v.trim() == "1")
        {
            info.bitrates.push(rate);
        }
    }
    if let Some(commissioning) = reader.sections.get("DEVICECOMISSIONING").cloned() {
        if let Some((value, line)) = commissioning.get("NodeID") {
            match number(value, None)
                .ok()
                .and_then(|v| u8::try_from(v).ok())
                .filter(|v| (1..=127).contains(v))
            {
                Some(node) => info.node_id = Some(node),
                None => reader.warn(
                    line,
                    format!("[DeviceComissioning] NodeID '{value}' is not 1..=127"),
                ),
            }
        }
        if let Some((value, _)) = commissioning.get("Baudrate") {
            info.bitrate = number(value, None).ok().and_then(|v| u32::try_from(v).ok());
        }
    }
    info
}

/// The sub-sections `[xxxxSUBn]` of an index, by sub-index.
fn sub_sections(reader: &Reader, index: u16) -> Vec<(u8, Section)> {
    let prefix = format!("{index:04X}SUB");
    reader
        .sections
        .iter()
        .filter_map(|(name, section)| {
            let sub = name.strip_prefix(&prefix)?;
            let sub = u8::from_str_radix(sub, 16).ok()?;
            Some((sub, section.clone()))
        })
        .collect()
}

fn read_object(reader: &mut Reader, od: &mut ObjectDictionary, index: u16, line: usize) {
    let Some(section) = reader.sections.get(&format!("{index:04X}")).cloned() else {
        return;
    };
    let name = section.get("ParameterName").map_or_else(
        || {
            reader.warn(line, format!("[{index:04X}] has no ParameterName"));
            format!("Object {index:04X}")
        },
        |(v, _)| v.to_string(),
    );
    let object_type = match section.get("ObjectType") {
        None => 7,
        Some((value, line)) => match number(value, None) {
            Ok(code) => code,
            Err(problem) => {
                reader.error(line, format!("[{index:04X}] ObjectType: {problem}"));
                return;
            }
        },
    };
    match object_type {
        // DOMAIN objects are variables whose type is DOMAIN.
        2 | 7 => {
            if let Some(entry) = read_entry(reader, index, 0, &section, None) {
                od.add_var(index, entry);
            }
        }
        8 | 9 => {
            let kind = if object_type == 8 { ObjectKind::Array } else { ObjectKind::Record };
            let mut entries = Vec::new();
            if let Some((count, count_line)) = section.get("CompactSubObj") {
                let count = number(count, None).ok().and_then(|v| u8::try_from(v).ok()).unwrap_or(0);
                if count == 0 {
                    reader.error(count_line, format!("[{index:04X}] CompactSubObj '{}' is not 1..=254", section.get("CompactSubObj").map_or("", |(v, _)| v)));
                    return;
                }
                let names = reader.sections.get(&format!("{index:04X}NAME")).cloned();
                for sub in 1..=count {
                    if let Some(mut entry) = read_entry(reader, index, sub, &section, None) {
                        if let Some((custom, _)) = names.as_ref().and_then(|n| n.get(&sub.to_string())) {
                            entry.name = custom.to_string();
                        } else {
                            entry.name = format!("{name}{sub}");
                        }
                        entries.push(entry);
                    }
                }
            } else {
                let subs = sub_sections(reader, index);
                if subs.is_empty() {
                    reader.error(line, format!("[{index:04X}] is {} with no sub-objects ([{index:04X}sub0], ...)", if kind == ObjectKind::Array { "an ARRAY" } else { "a RECORD" }));
                    return;
                }
                if let Some((declared, declared_line)) = section.get("SubNumber") {
                    let declared = number(declared, None).unwrap_or(-1);
                    if usize::try_from(declared).ok() != Some(subs.len()) {
                        reader.warn(declared_line, format!("[{index:04X}] SubNumber={declared} but {} sub-objects are described", subs.len()));
                    }
                }
                // Array members without a DataType take the array's.
                let array_type = subs.iter().find(|(sub, _)| *sub == 1).and_then(|(_, s)| s.get("DataType")).and_then(|(v, _)| number(v, None).ok()).and_then(|c| u16::try_from(c).ok()).and_then(DataType::from_code);
                for (sub, sub_section) in &subs {
                    let fallback = if kind == ObjectKind::Array && *sub > 0 { array_type } else { None };
                    if let Some(entry) = read_entry(reader, index, *sub, sub_section, fallback) {
                        entries.push(entry);
                    }
                }
            }
            od.add_object(index, &name, kind, entries);
        }
        0 | 5 | 6 => reader.warn(line, format!("[{index:04X}] is a type definition (ObjectType {object_type}); skipped")),
        other => reader.error(line, format!("[{index:04X}] ObjectType {other} is not VAR (7), ARRAY (8), RECORD (9) or DOMAIN (2)")),
    }
}

fn read_entry(
    reader: &mut Reader,
    index: u16,
    sub: u8,
    section: &Section,
    fallback_type: Option<DataType>,
) -> Option<Entry> {
    let where_ = if sub == 0 && fallback_type.is_none() && section.get("ParameterName").is_some() {
        format!("[{index:04X}]")
    } else {
        format!("{index:04X}sub{sub:X}")
    };
    let name = section
        .get("ParameterName")
        .map_or_else(|| format!("Sub {sub}"), |(v, _)| v.to_string());
    let data_type = match section.get("DataType") {
        Some((value, line)) => {
            match number(value, None)
                .ok()
                .and_then(|c| u16::try_from(c).ok())
                .and_then(DataType::from_code)
            {
                Some(data_type) => data_type,
                None => {
                    reader.error(line, format!("{where_}: DataType '{value}' is not a CiA 301 basic type; object left out"));
                    return None;
                }
            }
        }
        None => match fallback_type {
            Some(data_type) => {
                reader.warn(
                    section.line,
                    format!("{where_}: no DataType; the array's {data_type} is used"),
                );
                data_type
            }
            None => {
                reader.error(
                    section.line,
                    format!("{where_}: no DataType; object left out"),
                );
                return None;
            }
        },
    };
    let access = match section.get("AccessType") {
        Some((value, line)) => Access::from_eds(value).unwrap_or_else(|| {
            reader.warn(
                line,
                format!("{where_}: AccessType '{value}' unknown; read-only assumed"),
            );
            Access::ReadOnly
        }),
        None => {
            reader.warn(
                section.line,
                format!("{where_}: no AccessType; read-only assumed"),
            );
            Access::ReadOnly
        }
    };
    let mut entry = Entry::new(sub, &name, data_type, access);
    if section
        .get("PDOMapping")
        .is_some_and(|(v, _)| number(v, None).unwrap_or(0) != 0)
    {
        entry = entry.mappable();
    }
    let node_id = reader.node_id;
    let value_of = |reader: &mut Reader, key: &str| -> Option<Vec<u8>> {
        let (text, line) = section.get(key)?;
        match value_bytes(data_type, text, node_id) {
            Ok(bytes) => bytes,
            Err(problem) => {
                reader.warn(line, format!("{where_}: {key} {problem}; zero used"));
                None
            }
        }
    };
    // A DCF's ParameterValue is what the device is configured to; the default stays the EDS's.
    let default = value_of(reader, "DefaultValue");
    let configured = value_of(reader, "ParameterValue");
    if let Some(bytes) = configured.or(default) {
        entry = entry.with_default(&bytes);
    }
    let limit = |reader: &mut Reader, key: &str| -> Option<Number> {
        let (text, line) = section.get(key)?;
        if text.is_empty() {
            return None;
        }
        let bytes = match value_bytes(data_type, text, node_id) {
            Ok(bytes) => bytes?,
            Err(problem) => {
                reader.warn(line, format!("{where_}: {key} {problem}; no limit"));
                return None;
            }
        };
        Number::decode(data_type, &bytes)
    };
    let low = limit(reader, "LowLimit");
    let high = limit(reader, "HighLimit");
    Some(entry.with_limits(low, high))
}

/// A value as bytes of `data_type`; `Ok(None)` for an empty value.
fn value_bytes(
    data_type: DataType,
    text: &str,
    node_id: Option<u8>,
) -> Result<Option<Vec<u8>>, String> {
    if text.is_empty() {
        return Ok(None);
    }
    match data_type {
        DataType::Integer(_) | DataType::Unsigned(_) | DataType::Boolean => {
            let value = number(text, node_id)?;
            data_type.parse(&value.to_string()).map(Some)
        }
        _ => data_type.parse(text).map(Some),
    }
}

fn check_lists(reader: &mut Reader, indices: &[(u16, usize)]) {
    let mut listed = Vec::new();
    for list in ["MANDATORYOBJECTS", "OPTIONALOBJECTS", "MANUFACTUREROBJECTS"] {
        let Some(section) = reader.sections.get(list).cloned() else {
            continue;
        };
        for (key, (value, line)) in &section.keys {
            if key == "supportedobjects" {
                continue;
            }
            match number(value, None).ok().and_then(|v| u16::try_from(v).ok()) {
                Some(index) => {
                    if !indices.iter().any(|(i, _)| *i == index) {
                        reader.error(
                            *line,
                            format!(
                                "object 0x{index:04X} is listed but has no [{index:04X}] section"
                            ),
                        );
                    }
                    listed.push(index);
                }
                None => reader.warn(*line, format!("'{value}' in [{list}] is not an index")),
            }
        }
    }
    if !listed.is_empty() {
        for (index, line) in indices {
            if !listed.contains(index) {
                reader.warn(
                    *line,
                    format!("[{index:04X}] is described but not listed in any object list"),
                );
            }
        }
    }
}

/// Write a dictionary as an EDS (CiA 306) that python-canopen and this module read back.
/// With `node`, COB-IDs that hold it (EMCY, PDOs) are written as `$NODEID+base`, so the file
/// describes the device at any node ID.
pub fn write(od: &ObjectDictionary, info: &DeviceInfo, node: Option<u8>) -> String {
    use core::fmt::Write;
    let mut out = String::new();
    let _ = writeln!(out, "[FileInfo]\nFileName=device.eds\nFileVersion=1\nFileRevision=0\nEDSVersion=4.0\nDescription=written by bywire-canopen\nCreatedBy=bywire\n");
    let _ = writeln!(out, "[DeviceInfo]\nVendorName={}\nVendorNumber=0x{:08X}\nProductName={}\nProductNumber=0x{:08X}\nRevisionNumber=0x{:08X}", info.vendor_name, info.vendor_number, info.product_name, info.product_number, info.revision_number);
    for rate in [10, 20, 50, 125, 250, 500, 800, 1000] {
        let _ = writeln!(
            out,
            "BaudRate_{rate}={}",
            u8::from(info.bitrates.contains(&rate))
        );
    }
    let count = |range: core::ops::RangeInclusive<u16>| {
        od.objects()
            .iter()
            .filter(|o| range.contains(&o.index))
            .count()
    };
    let _ = writeln!(
        out,
        "SimpleBootUpMaster=0\nSimpleBootUpSlave=1\nGranularity=8\nDynamicChannelsSupported=0\nGroupMessaging=0\nNrOfRXPDO={}\nNrOfTXPDO={}\nLSS_Supported=0\n",
        count(0x1400..=0x15FF),
        count(0x1800..=0x19FF)
    );
    let _ = writeln!(out, "[DummyUsage]\nDummy0001=0\nDummy0002=1\nDummy0003=1\nDummy0004=1\nDummy0005=1\nDummy0006=1\nDummy0007=1\n");
    let mandatory = [0x1000u16, 0x1001, 0x1018];
    let lists: [(&str, Vec<u16>); 3] = [
        (
            "MandatoryObjects",
            od.objects()
                .iter()
                .map(|o| o.index)
                .filter(|i| mandatory.contains(i))
                .collect(),
        ),
        (
            "OptionalObjects",
            od.objects()
                .iter()
                .map(|o| o.index)
                .filter(|i| !mandatory.contains(i) && !(0x2000..=0x5FFF).contains(i))
                .collect(),
        ),
        (
            "ManufacturerObjects",
            od.objects()
                .iter()
                .map(|o| o.index)
                .filter(|i| (0x2000..=0x5FFF).contains(i))
                .collect(),
        ),
    ];
    for (name, indices) in &lists {
        let _ = writeln!(out, "[{name}]\nSupportedObjects={}", indices.len());
        for (n, index) in indices.iter().enumerate() {
            let _ = writeln!(out, "{}=0x{index:04X}", n + 1);
        }
        let _ = writeln!(out);
    }
    for object in od.objects() {
        let index = object.index;
        match object.kind {
            ObjectKind::Var => {
                if let Some(entry) = object.entries().first() {
                    let _ = writeln!(out, "[{index:04X}]");
                    write_entry(&mut out, index, entry, node);
                }
            }
            ObjectKind::Array | ObjectKind::Record => {
                let _ = writeln!(
                    out,
                    "[{index:04X}]\nParameterName={}\nObjectType=0x{:X}\nSubNumber={}\n",
                    object.name,
                    object.kind.code(),
                    object.entries().len()
                );
                for entry in object.entries() {
                    let _ = writeln!(out, "[{index:04X}sub{:X}]", entry.sub);
                    write_entry(&mut out, index, entry, node);
                }
            }
        }
    }
    out
}

/// COB-ID entries whose identifier is usually the node ID plus a base.
fn is_node_cob_id(index: u16, sub: u8) -> bool {
    (index == 0x1014 && sub == 0)
        || (matches!(index, 0x1400..=0x15FF | 0x1800..=0x19FF) && sub == 1)
}

fn write_entry(out: &mut String, index: u16, entry: &Entry, node: Option<u8>) {
    use core::fmt::Write;
    let relative = match (node, Number::decode(entry.data_type, entry.default_value())) {
        (Some(node), Some(Number::Uint(cob)))
            if is_node_cob_id(index, entry.sub) && cob & 0x7F == u64::from(node) && node != 0 =>
        {
            Some(format!("$NODEID+0x{:X}", cob - u64::from(node)))
        }
        _ => None,
    };
    let default = relative.unwrap_or_else(|| match entry.data_type {
        DataType::Integer(_)
        | DataType::Unsigned(_)
        | DataType::Boolean
        | DataType::Real32
        | DataType::Real64 => match Number::decode(entry.data_type, entry.default_value()) {
            Some(Number::Uint(v)) => format!("0x{v:X}"),
            Some(number) => number.to_string(),
            None => String::new(),
        },
        DataType::VisibleString | DataType::UnicodeString => {
            entry.data_type.format(entry.default_value())
        }
        // Octet strings and domains: hex bytes without spaces.
        _ => entry
            .default_value()
            .iter()
            .map(|b| format!("{b:02X}"))
            .collect(),
    });
    let _ = writeln!(out, "ParameterName={}\nObjectType=0x7\nDataType=0x{:04X}\nAccessType={}\nDefaultValue={default}\nPDOMapping={}", entry.name, entry.data_type.code(), entry.access.eds_name(), u8::from(entry.pdo_mappable));
    for (key, limit) in [("LowLimit", entry.low), ("HighLimit", entry.high)] {
        if let Some(limit) = limit {
            let _ = writeln!(out, "{key}={limit}");
        }
    }
    let _ = writeln!(out);
}

#[cfg(test)]
mod tests {
    use super::*;

    const VENDOR_FILE: &str = "\u{feff}[FileInfo]\r\nFileName=x.eds\r\n[DeviceInfo]\r\nVendorName=Acme ; a comment\r\nVendorNumber=0x2F7\r\nProductName=Widget\r\nBaudRate_500=1\r\nBaudRate_1000=1\r\n[MandatoryObjects]\r\nSupportedObjects=3\r\n1=0x1000\r\n2=0x1001\r\n3=0x1018\r\n[OptionalObjects]\r\nSupportedObjects=3\r\n1=0x1800\r\n2=0x1016\r\n3=0x1A00\r\n[1000]\r\nParameterName=Device type\r\nDataType=0x0007\r\nAccessType=RO\r\nDefaultValue=0x00020192\r\n[1001]\r\nParameterName=Error register\r\nObjectType=0x7\r\nDataType=0x0005\r\nAccessType=ro\r\nDefaultValue=\r\nPDOMapping=1\r\n[1800]\r\nParameterName=TPDO1\r\nObjectType=0x9\r\nSubNumber=4\r\n[1800sub0]\r\nParameterName=Highest\r\nDataType=0x0005\r\nAccessType=const\r\nDefaultValue=2\r\n[1800sub1]\r\nParameterName=COB-ID\r\nDataType=0x0007\r\nAccessType=rw\r\nDefaultValue=$NODEID+0x180\r\n[1800sub2]\r\nParameterName=Type\r\nDataType=0x0005\r\nAccessType=rw\r\nDefaultValue=0377\r\n[1016]\r\nParameterName=Consumer heartbeat time\r\nObjectType=0x8\r\nDataType=0x0007\r\nAccessType=rw\r\nCompactSubObj=2\r\n[1016Name]\r\n1=First consumer\r\n[1A00]\r\nParameterName=broken\r\nObjectType=0x9\r\n[2000]\r\nParameterName=Speed\r\nDataType=0x0003\r\nAccessType=rww\r\nPDOMapping=1\r\nLowLimit=-1000\r\nHighLimit=1000\r\nDefaultValue=-5\r\n[2001]\r\nParameterName=Odd\r\nDataType=0x0099\r\nAccessType=rw\r\n";

    #[test]
    fn a_vendor_file_with_its_quirks_reads_with_diagnostics() {
        let eds = parse(VENDOR_FILE, Some(5)).unwrap();
        let od = &eds.dictionary;
        assert_eq!(eds.info.vendor_name, "Acme");
        assert_eq!(eds.info.vendor_number, 0x2F7);
        assert_eq!(eds.info.bitrates, [500, 1000]);
        assert_eq!(od.get_unsigned(0x1000, 0), Some(0x0002_0192));
        assert_eq!(od.get_unsigned(0x1800, 1), Some(0x185), "$NODEID+0x180");
        assert_eq!(od.get_unsigned(0x1800, 2), Some(255), "0377 is octal");
        assert_eq!(od.get_signed(0x2000, 0), Some(-5));
        assert_eq!(od.entry(0x2000, 0).unwrap().access, Access::ReadWriteWrite);
        assert!(od.entry(0x2000, 0).unwrap().pdo_mappable);
        assert_eq!(
            od.check_write(0x2000, 0, &2000i16.to_le_bytes()),
            Err(crate::Abort::ValueTooHigh)
        );
        assert_eq!(od.entry(0x1016, 1).unwrap().name, "First consumer");
        assert_eq!(
            od.entry(0x1016, 2).unwrap().name,
            "Consumer heartbeat time2"
        );
        assert_eq!(od.get_unsigned(0x1016, 0), Some(2));
        let messages: Vec<String> = eds.diagnostics.iter().map(ToString::to_string).collect();
        let has = |needle: &str| messages.iter().any(|m| m.contains(needle));
        assert!(has("SubNumber=4 but 3 sub-objects"), "{messages:#?}");
        assert!(
            has("[1A00] is a RECORD with no sub-objects"),
            "{messages:#?}"
        );
        assert!(
            has("object 0x1018 is listed but has no [1018] section"),
            "{messages:#?}"
        );
        assert!(
            has("DataType '0x0099' is not a CiA 301 basic type"),
            "{messages:#?}"
        );
        assert!(has("[2000] is described but not listed"), "{messages:#?}");
        assert!(eds
            .diagnostics
            .iter()
            .all(|d| d.line > 0 || d.message.contains("DeviceInfo")));
        assert!(od.object(0x2001).is_none() && od.object(0x1A00).is_none());
    }

    #[test]
    fn node_id_is_needed_for_nodeid_values_and_dcf_gives_one() {
        let eds = parse(VENDOR_FILE, None).unwrap();
        assert!(eds
            .diagnostics
            .iter()
            .any(|d| d.message.contains("uses $NODEID but no node ID is known")));
        let dcf = VENDOR_FILE.replace(
            "[FileInfo]",
            "[DeviceComissioning]\r\nNodeID=0x10\r\nBaudrate=500\r\n[FileInfo]",
        );
        let eds = parse(&dcf, None).unwrap();
        assert_eq!(eds.info.node_id, Some(16));
        assert_eq!(eds.dictionary.get_unsigned(0x1800, 1), Some(0x190));
        assert_eq!(parse("just text", None).unwrap_err().line, 1);
    }

    #[test]
    fn written_files_read_back_into_the_same_dictionary() {
        let od = crate::cia402::drive_dictionary(3);
        let info = DeviceInfo {
            vendor_name: "bywire".into(),
            product_name: "drive".into(),
            bitrates: alloc::vec![1000],
            ..DeviceInfo::default()
        };
        let text = write(&od, &info, Some(3));
        assert!(text.contains("DefaultValue=$NODEID+0x180\n"), "{text}");
        let eds = parse(&text, Some(3)).unwrap();
        assert_eq!(eds.diagnostics, [], "{text}");
        assert_eq!(eds.dictionary, od);
        assert_eq!(eds.info.product_name, "drive");
        // The same file describes the device at another node ID.
        let moved = parse(&text, Some(9)).unwrap().dictionary;
        assert_eq!(moved.get_unsigned(0x1800, 1), Some(0x189));
        assert_eq!(moved.get_unsigned(0x1014, 0), Some(0x89));
    }

    /// Reals are written as numbers (and read back the same, NaN and infinities too), not as
    /// their bytes.
    #[test]
    fn reals_are_written_as_numbers() {
        let text = "[DeviceInfo]\nProductName=x\n[2000]\nParameterName=Gain\nDataType=0x0008\nAccessType=rw\nDefaultValue=0.1\n\
                    [2001]\nParameterName=Offset\nDataType=0x0011\nAccessType=rw\nDefaultValue=-2.5e-3\n\
                    [2002]\nParameterName=Unset\nDataType=0x0011\nAccessType=rw\nDefaultValue=NaN\n\
                    [2003]\nParameterName=Far\nDataType=0x0008\nAccessType=rw\nDefaultValue=-inf\n";
        let read = parse(text, None).unwrap();
        assert_eq!(read.diagnostics, []);
        let written = write(&read.dictionary, &read.info, None);
        for value in ["0.10000000149011612", "-0.0025", "NaN", "-inf"] {
            assert!(
                written.contains(&format!("DefaultValue={value}\n")),
                "{written}"
            );
        }
        let again = parse(&written, None).unwrap();
        assert_eq!(again.diagnostics, []);
        assert_eq!(again.dictionary, read.dictionary);
    }
}
