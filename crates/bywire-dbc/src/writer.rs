//! DBC text from a [`Database`]: what the parser reads back into an equal database.

use std::fmt::Write;

use crate::model::*;

fn quoted(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 2);
    out.push('"');
    for c in s.chars() {
        if c == '"' || c == '\\' {
            out.push('\\');
        }
        out.push(c);
    }
    out.push('"');
    out
}

fn attr(v: &AttrValue) -> String {
    match v {
        AttrValue::Number(n) => n.to_string(),
        AttrValue::Str(s) => quoted(s),
    }
}

fn pairs(values: &[(i128, String)]) -> String {
    values
        .iter()
        .map(|(v, d)| format!(" {v} {}", quoted(d)))
        .collect()
}

/// Write `db` as DBC text.
pub fn write(db: &Database) -> String {
    let mut o = String::new();
    // Writing to a String cannot fail.
    let _ = write_into(db, &mut o);
    o
}

fn write_into(db: &Database, o: &mut String) -> std::fmt::Result {
    header(db, o)?;
    messages(db, o)?;
    comments(db, o)?;
    attributes(db, o)?;
    value_descriptions_and_extras(db, o)?;
    // Statements kept verbatim go last: one whose string runs to the end of the file (which is
    // how it was read) would otherwise swallow whatever followed it.
    for u in &db.unknown {
        writeln!(o, "{u}")?;
    }
    Ok(())
}

/// `VERSION`, `NS_`, `BS_`, `BU_` and the value tables.
fn header(db: &Database, o: &mut String) -> std::fmt::Result {
    writeln!(o, "VERSION {}\n", quoted(&db.version))?;
    writeln!(o, "NS_ :")?;
    for s in &db.new_symbols {
        writeln!(o, "\t{s}")?;
    }
    writeln!(o, "\nBS_: {}\n", db.bit_timing)?;
    let nodes: Vec<&str> = db.nodes.iter().map(|n| n.name.as_str()).collect();
    writeln!(o, "BU_: {}\n", nodes.join(" "))?;
    for (name, values) in &db.value_tables {
        writeln!(o, "VAL_TABLE_ {name}{};", pairs(values))?;
    }
    Ok(())
}

/// `BO_` with their `SG_`, then `BO_TX_BU_` and `EV_`.
fn messages(db: &Database, o: &mut String) -> std::fmt::Result {
    for m in &db.messages {
        writeln!(
            o,
            "\nBO_ {} {}: {} {}",
            m.raw_id(),
            m.name,
            m.size,
            m.transmitter
        )?;
        for s in &m.signals {
            let mux = match s.multiplexing {
                Multiplexing::None => String::new(),
                Multiplexing::Multiplexor => " M".into(),
                Multiplexing::Multiplexed(v) => format!(" m{v}"),
                Multiplexing::MultiplexedMultiplexor(v) => format!(" m{v}M"),
            };
            let order = match s.byte_order {
                ByteOrder::BigEndian => 0,
                ByteOrder::LittleEndian => 1,
            };
            let sign = match s.value_type {
                ValueType::Integer { signed: false } => '+',
                _ => '-',
            };
            let receivers = s.receivers.join(",");
            writeln!(
                o,
                " SG_ {}{mux} : {}|{}@{order}{sign} ({},{}) [{}|{}] {} {receivers}",
                s.name,
                s.start_bit,
                s.length,
                s.factor,
                s.offset,
                s.minimum,
                s.maximum,
                quoted(&s.unit)
            )?;
        }
    }
    writeln!(o)?;
    for m in db.messages.iter().filter(|m| !m.senders.is_empty()) {
        writeln!(o, "BO_TX_BU_ {} : {};", m.raw_id(), m.senders.join(","))?;
    }
    for e in &db.env_vars {
        writeln!(o, "EV_ {}: {};", e.name, e.definition)?;
    }
    Ok(())
}

/// `CM_`: the network's, then nodes', messages' and signals', environment variables'.
fn comments(db: &Database, o: &mut String) -> std::fmt::Result {
    if let Some(c) = &db.comment {
        writeln!(o, "CM_ {};", quoted(c))?;
    }
    for n in &db.nodes {
        if let Some(c) = &n.comment {
            writeln!(o, "CM_ BU_ {} {};", n.name, quoted(c))?;
        }
    }
    for m in &db.messages {
        if let Some(c) = &m.comment {
            writeln!(o, "CM_ BO_ {} {};", m.raw_id(), quoted(c))?;
        }
        for s in &m.signals {
            if let Some(c) = &s.comment {
                writeln!(o, "CM_ SG_ {} {} {};", m.raw_id(), s.name, quoted(c))?;
            }
        }
    }
    for e in &db.env_vars {
        if let Some(c) = &e.comment {
            writeln!(o, "CM_ EV_ {} {};", e.name, quoted(c))?;
        }
    }
    Ok(())
}

/// `BA_DEF_`, `BA_DEF_DEF_` and `BA_` for every object.
fn attributes(db: &Database, o: &mut String) -> std::fmt::Result {
    for d in &db.attribute_defs {
        let scope = match d.scope {
            AttrScope::Network => "",
            AttrScope::Node => "BU_ ",
            AttrScope::Message => "BO_ ",
            AttrScope::Signal => "SG_ ",
            AttrScope::EnvVar => "EV_ ",
        };
        let kind = match &d.kind {
            AttrType::Int(a, b) => format!("INT {a} {b}"),
            AttrType::Hex(a, b) => format!("HEX {a} {b}"),
            AttrType::Float(a, b) => format!("FLOAT {a} {b}"),
            AttrType::Str => "STRING".into(),
            AttrType::Enum(v) => format!(
                "ENUM {}",
                v.iter().map(|s| quoted(s)).collect::<Vec<_>>().join(",")
            ),
        };
        writeln!(o, "BA_DEF_ {scope}{} {kind};", quoted(&d.name))?;
    }
    for d in &db.attribute_defs {
        if let Some(v) = &d.default {
            writeln!(o, "BA_DEF_DEF_ {} {};", quoted(&d.name), attr(v))?;
        }
    }
    for (name, v) in &db.attributes {
        writeln!(o, "BA_ {} {};", quoted(name), attr(v))?;
    }
    for n in &db.nodes {
        for (name, v) in &n.attributes {
            writeln!(o, "BA_ {} BU_ {} {};", quoted(name), n.name, attr(v))?;
        }
    }
    for m in &db.messages {
        for (name, v) in &m.attributes {
            writeln!(o, "BA_ {} BO_ {} {};", quoted(name), m.raw_id(), attr(v))?;
        }
        for s in &m.signals {
            for (name, v) in &s.attributes {
                writeln!(
                    o,
                    "BA_ {} SG_ {} {} {};",
                    quoted(name),
                    m.raw_id(),
                    s.name,
                    attr(v)
                )?;
            }
        }
    }
    for e in &db.env_vars {
        for (name, v) in &e.attributes {
            writeln!(o, "BA_ {} EV_ {} {};", quoted(name), e.name, attr(v))?;
        }
    }
    Ok(())
}

/// `VAL_`, `SIG_GROUP_`, `SIG_VALTYPE_` and `SG_MUL_VAL_`.
fn value_descriptions_and_extras(db: &Database, o: &mut String) -> std::fmt::Result {
    for m in &db.messages {
        for s in m
            .signals
            .iter()
            .filter(|s| !s.value_descriptions.is_empty())
        {
            writeln!(
                o,
                "VAL_ {} {}{};",
                m.raw_id(),
                s.name,
                pairs(&s.value_descriptions)
            )?;
        }
    }
    for e in db
        .env_vars
        .iter()
        .filter(|e| !e.value_descriptions.is_empty())
    {
        writeln!(o, "VAL_ {}{};", e.name, pairs(&e.value_descriptions))?;
    }
    for g in &db.signal_groups {
        writeln!(
            o,
            "SIG_GROUP_ {} {} {} : {};",
            g.message_raw_id,
            g.name,
            g.repetitions,
            g.signals.join(" ")
        )?;
    }
    for m in &db.messages {
        for s in &m.signals {
            let code = match s.value_type {
                ValueType::Integer { .. } => continue,
                ValueType::Float32 => 1,
                ValueType::Float64 => 2,
            };
            writeln!(o, "SIG_VALTYPE_ {} {} : {code};", m.raw_id(), s.name)?;
        }
    }
    for m in &db.messages {
        for s in &m.signals {
            if let Some(c) = &s.mux_condition {
                let ranges: Vec<String> =
                    c.ranges.iter().map(|(a, b)| format!("{a}-{b}")).collect();
                writeln!(
                    o,
                    "SG_MUL_VAL_ {} {} {} {};",
                    m.raw_id(),
                    s.name,
                    c.switch,
                    ranges.join(", ")
                )?;
            }
        }
    }
    Ok(())
}
