//! Frames to named signal values with a DBC, shared by `decode`, `dump --dbc`, `monitor`,
//! `sniff` and `plot`: one place that finds a frame's message, decodes it and shows values the
//! way cantools does (value descriptions, units, Python's float text).

use anyhow::{anyhow, Result};
use bywire_core::{FdFrame, Frame, Id};
use bywire_dbc::codec::{EncodeMode, Value};
use bywire_dbc::named::{encode_named, Encoding, Given, Named};
use bywire_dbc::{Database, Message, Signal};
use serde_json::json;

pub use bywire_dbc::decoder::{DecodedFrame, Decoder, SignalValue};

/// How cantools shows a decoded value.
pub trait ValueText {
    /// The value description if there is one (unless `choices` is off), else the number with
    /// its unit.
    fn text(&self, choices: bool) -> String;
}

impl ValueText for SignalValue<'_> {
    fn text(&self, choices: bool) -> String {
        let mut text = String::new();
        push_value_text(&mut text, self, choices);
        text
    }
}

/// Push what [`ValueText::text`] gives.
fn push_value_text(line: &mut String, value: &SignalValue<'_>, choices: bool) {
    // (Most signals have no value descriptions: none looked up.)
    let described = choices && !value.signal.value_descriptions.is_empty();
    match described.then(|| value.description()).flatten() {
        Some(name) => line.push_str(name),
        None => {
            push_number_text(line, value.value.physical);
            if !value.signal.unit.is_empty() {
                line.push(' ');
                line.push_str(&value.signal.unit);
            }
        }
    }
}

/// A database compiled for decoding ([`Decoder`], which does the work), with what the commands
/// add: messages found by name with an error naming the known ones, and messages encoded from
/// `SIGNAL=VALUE` text.
pub struct Dbc(Decoder);

impl Dbc {
    /// Compile every message of `db`.
    pub fn new(db: Database) -> Self {
        Dbc(Decoder::new(db))
    }

    /// The compiled database.
    pub fn decoder(&self) -> &Decoder {
        &self.0
    }

    /// The message named `name` (or with identifier `name` in hex, `0x` optional).
    pub fn find(&self, name: &str) -> Result<&Message> {
        self.0.message_named(name).ok_or_else(|| {
            let messages = &self.0.database().messages;
            let known: Vec<&str> = messages.iter().take(8).map(|m| m.name.as_str()).collect();
            anyhow!(
                "no message '{name}' in the DBC (it has: {}{})",
                known.join(", "),
                if messages.len() > known.len() {
                    ", ..."
                } else {
                    ""
                }
            )
        })
    }

    /// Encode a message from `SIGNAL=VALUE` assignments (numbers, or value-description names)
    /// by [`encode_named`]: signals not given take their `GenSigStartValue` or 0 bits; values
    /// outside a signal's range are refused naming the signal (or clamped, with
    /// `EncodeMode::Clamp`); the counter and checksum, when the message has them, are filled
    /// in with `counter`.
    pub fn encode(
        &self,
        message: &Message,
        assignments: &[String],
        counter: u64,
        range: EncodeMode,
    ) -> Result<Frame> {
        let codec = self
            .0
            .codec(message)
            .ok_or_else(|| anyhow!("message {} is not in the DBC", message.name))?;
        let values = assignments
            .iter()
            .map(|assignment| {
                let (signal, text) = assignment
                    .split_once('=')
                    .ok_or_else(|| anyhow!("'{assignment}' is not SIGNAL=VALUE"))?;
                Ok(Named {
                    signal,
                    value: Given::from_text(text),
                    shown: text,
                })
            })
            .collect::<Result<Vec<_>>>()?;
        let payload = encode_named(message, codec, &values, Encoding::frame(range, counter))?;
        let id = if message.extended {
            Id::extended(message.id)
        } else {
            Id::standard(message.id)
        }
        .map_err(|e| anyhow!("message {}: {e}", message.name))?;
        let (fd, brs) = self.0.fd_format(message);
        let frame = if fd {
            Frame::Fd(FdFrame::padded(id, &payload, brs, false)?)
        } else {
            Frame::classic(id, &payload)?
        };
        Ok(frame)
    }
}

/// How cantools shows a decoded frame.
pub trait FrameText {
    /// cantools' single-line form: `Name(sig: value, ...)`.
    fn single_line(&self, choices: bool) -> String;
    /// cantools' multi-line form: `Name(\n    sig: value,\n ...\n)`, each line after the
    /// first prefixed with `indent`.
    fn multi_line(&self, choices: bool, indent: &str) -> String;
    /// The signals as a JSON object of name to physical value.
    fn json_signals(&self) -> serde_json::Map<String, serde_json::Value>;
}

/// Push the frame's `signal: value` items, `separator` between them: into one string, not a
/// string per item (decoding a log spends its time here). In cantools' order: by start bit in
/// network order, the file's order among equals (a stable sort; most files list them so).
fn push_items(line: &mut String, frame: &DecodedFrame<'_>, choices: bool, separator: &str) {
    let mut ordered: Vec<&SignalValue<'_>> = frame.signals.iter().collect();
    ordered.sort_by_key(|s| s.signal.network_start_bit());
    for (i, s) in ordered.into_iter().enumerate() {
        if i > 0 {
            line.push_str(separator);
        }
        line.push_str(s.signal.display_name());
        line.push_str(": ");
        push_value_text(line, s, choices);
    }
}

impl FrameText for DecodedFrame<'_> {
    fn single_line(&self, choices: bool) -> String {
        let mut line = String::with_capacity(64 + 32 * self.signals.len());
        line.push_str(self.message.display_name());
        line.push('(');
        push_items(&mut line, self, choices, ", ");
        line.push(')');
        line
    }

    fn multi_line(&self, choices: bool, indent: &str) -> String {
        let mut text = String::with_capacity(64 + 40 * self.signals.len());
        text.push_str(self.message.display_name());
        text.push_str("(\n");
        text.push_str(indent);
        text.push_str("    ");
        push_items(&mut text, self, choices, &format!(",\n{indent}    "));
        text.push('\n');
        text.push_str(indent);
        text.push(')');
        text
    }

    /// A name used twice in one message (a warning when the DBC loads) keeps both values:
    /// the second as `NAME#2`, a third as `NAME#3`.
    fn json_signals(&self) -> serde_json::Map<String, serde_json::Value> {
        let mut object = serde_json::Map::new();
        for s in &self.signals {
            let name = s.signal.display_name();
            let key = (1..=self.signals.len())
                .map(|n| match n {
                    1 => name.to_string(),
                    n => format!("{name}#{n}"),
                })
                .find(|key| !object.contains_key(key))
                .unwrap_or_else(|| name.to_string());
            object.insert(key, json_number(s.value.physical));
        }
        object
    }
}

/// `decode`'s text lines (cantools' multi-line and single-line forms, after the frame's own
/// line) written straight out: each message's name and its signals in cantools' order (by
/// start bit in network order, the file's order among equals), found once, not per frame;
/// values written into one reused line.
pub struct TextLines<'a> {
    dbc: &'a Dbc,
    /// By message index (contained PDUs after the messages, as the decoder numbers them): its
    /// name and its signals' indices and names in cantools' order.
    messages: Vec<(String, Vec<(usize, String)>)>,
    values: Vec<Option<bywire_dbc::codec::Decoded>>,
    line: String,
}

impl<'a> TextLines<'a> {
    /// Lines of frames decoded with `dbc`, one per frame (`single_line`) or one per signal.
    pub fn new(dbc: &'a Dbc) -> Self {
        let decoder = dbc.decoder();
        let messages = (0..decoder.message_count())
            .filter_map(|i| decoder.message_at(i))
            .map(|(message, _)| shown_order(message))
            .collect();
        TextLines {
            dbc,
            messages,
            values: Vec::new(),
            line: String::new(),
        }
    }

    /// Write `text` (the frame's line) and what `frame` decodes to, as [`FrameText`] gives it:
    /// `text ::\nName(\n    a: 1,\n ...\n)`, `text :: Name(a: 1, ...)`, `text :: error`, or
    /// `text` alone for a frame of no message.
    pub fn write(
        &mut self,
        out: &mut impl std::io::Write,
        text: &str,
        frame: &Frame,
        single_line: bool,
        choices: bool,
    ) -> std::io::Result<()> {
        let line = &mut self.line;
        line.clear();
        line.push_str(text);
        match self.dbc.decoder().decode_into(frame, &mut self.values) {
            None => {}
            Some((_, _, Err(error))) => {
                line.push_str(" :: ");
                line.push_str(&error.to_string());
            }
            Some((index, message, Ok(()))) => {
                let (name, order) = self
                    .messages
                    .get(index)
                    .map_or(("", &[][..]), |(n, o)| (n.as_str(), o.as_slice()));
                if let Some(pdus) = self.dbc.decoder().contained(index, frame.data()) {
                    let shape = Shape {
                        single_line,
                        choices,
                        indent: "    ",
                    };
                    push_container(line, name, pdus, &self.messages, &shape);
                } else {
                    line.push_str(if single_line { " :: " } else { " ::\n" });
                    let shape = Shape {
                        single_line,
                        choices,
                        indent: "",
                    };
                    push_message(line, name, order, message, &self.values, &shape);
                }
            }
        }
        line.push('\n');
        out.write_all(line.as_bytes())
    }
}

/// A message's name and its signals' indices and names in cantools' order (by start bit in
/// network order, the file's order among equals).
fn shown_order(message: &bywire_dbc::Message) -> (String, Vec<(usize, String)>) {
    let mut order: Vec<(usize, String)> = message
        .signals
        .iter()
        .map(|s| s.display_name().to_string())
        .enumerate()
        .collect();
    order.sort_by_key(|(i, _)| message.signals.get(*i).map(Signal::network_start_bit));
    (message.display_name().to_string(), order)
}

/// How `decode` lays a message out: on one line or one signal per line (indented by `indent`
/// more inside a container), value names or numbers.
struct Shape {
    single_line: bool,
    choices: bool,
    indent: &'static str,
}

/// `Name(a: 1, b: 2)` or, one signal per line, `Name(\n    a: 1,\n    b: 2\n)`.
fn push_message(
    line: &mut String,
    name: &str,
    order: &[(usize, String)],
    message: &bywire_dbc::Message,
    values: &[Option<bywire_dbc::codec::Decoded>],
    shape: &Shape,
) {
    line.push_str(name);
    line.push('(');
    if !shape.single_line {
        line.push('\n');
        line.push_str(shape.indent);
        line.push_str("    ");
    }
    let mut first = true;
    for (i, signal_name) in order {
        let (Some(Some(value)), Some(signal)) = (values.get(*i), message.signals.get(*i)) else {
            continue;
        };
        if !first {
            line.push(',');
            if shape.single_line {
                line.push(' ');
            } else {
                line.push('\n');
                line.push_str(shape.indent);
                line.push_str("    ");
            }
        }
        first = false;
        line.push_str(signal_name);
        line.push_str(": ");
        let value = SignalValue {
            signal,
            value: *value,
        };
        push_value_text(line, &value, shape.choices);
    }
    if !shape.single_line {
        line.push('\n');
        line.push_str(shape.indent);
    }
    line.push(')');
}

/// A container frame's PDUs as cantools shows them: `Container(A(x: 1), B(y: 2))` or, one per
/// block, each PDU's header ID and bytes (`000001##0a0b ::`) above its signals; a PDU the
/// database does not know, or cannot decode, said so; a frame that does not split, its error.
fn push_container<'d>(
    line: &mut String,
    name: &str,
    pdus: impl Iterator<
        Item = Result<
            bywire_dbc::decoder::Contained<'d, 'd>,
            bywire_dbc::container::ContainerError,
        >,
    >,
    orders: &[(String, Vec<(usize, String)>)],
    shape: &Shape,
) {
    use std::fmt::Write as _;
    let mut parts = String::new();
    let mut values = Vec::new();
    for (n, pdu) in pdus.enumerate() {
        let pdu = match pdu {
            Ok(pdu) => pdu,
            Err(error) => {
                line.push_str(" :: ");
                line.push_str(&error.to_string());
                return;
            }
        };
        if n > 0 {
            parts.push_str(if shape.single_line { ", " } else { ",\n" });
        }
        let hex = |sep: &str| {
            pdu.pdu
                .data
                .iter()
                .map(|b| format!("{b:02x}"))
                .collect::<Vec<_>>()
                .join(sep)
        };
        // (Writing to a String cannot fail.)
        if !shape.single_line {
            let _ = write!(parts, "    {:06x}##{} ::\n    ", pdu.pdu.header_id, hex(""));
        }
        let Some((message, codec, index)) = pdu.message else {
            if shape.single_line {
                let _ = write!(
                    parts,
                    "(Unknown contained message: Header ID: 0x{:x}, Data: {})",
                    pdu.pdu.header_id,
                    hex("")
                );
            } else {
                parts.push_str("Unknown contained message");
            }
            continue;
        };
        values.clear();
        values.resize(codec.signal_count(), None);
        if codec.decode(pdu.pdu.data, &mut values).is_err() {
            let _ = write!(parts, "{}: Undecodable data", message.display_name());
            if shape.single_line {
                let _ = write!(parts, ": {}", hex(" "));
            }
            continue;
        }
        let Some((pdu_name, order)) = orders.get(index) else {
            continue;
        };
        push_message(&mut parts, pdu_name, order, message, &values, shape);
    }
    if shape.single_line {
        line.push_str(" :: ");
        line.push_str(name);
        line.push('(');
        line.push_str(&parts);
        line.push(')');
    } else {
        line.push_str(" ::\n");
        line.push_str(name);
        line.push_str("(\n");
        line.push_str(&parts);
        line.push_str("\n)");
    }
}

/// `decode --json` lines written straight out: the bytes `serde_json` makes of the same object
/// (keys in its sorted order, its number and string forms) without a map, a value or a sort per
/// frame. Each message's signals are put in name order, their names quoted, once.
pub struct JsonLines<'a> {
    dbc: &'a Dbc,
    /// By message index; `None` where two signals share a name ([`FrameText::json_signals`]
    /// numbers those).
    messages: Vec<Option<MessageJson>>,
    values: Vec<Option<bywire_dbc::codec::Decoded>>,
}

/// A message's quoted name and its signals' indices with their quoted names, in name order.
struct MessageJson {
    name: String,
    signals: Vec<(usize, String)>,
}

impl<'a> JsonLines<'a> {
    /// Lines of frames decoded with `dbc`.
    pub fn new(dbc: &'a Dbc) -> Self {
        let quoted = |text: &str| serde_json::to_string(text).unwrap_or_default();
        let messages = dbc
            .decoder()
            .database()
            .messages
            .iter()
            .map(|message| {
                let mut signals: Vec<(usize, &str)> = message
                    .signals
                    .iter()
                    .map(Signal::display_name)
                    .enumerate()
                    .collect();
                signals.sort_unstable_by(|a, b| a.1.cmp(b.1));
                let shared_name = signals.windows(2).any(|pair| pair[0].1 == pair[1].1);
                (!shared_name).then(|| MessageJson {
                    name: quoted(message.display_name()),
                    signals: signals
                        .into_iter()
                        .map(|(index, name)| (index, quoted(name)))
                        .collect(),
                })
            })
            .collect();
        JsonLines {
            dbc,
            messages,
            values: Vec::new(),
        }
    }

    /// Write `frame`'s line; `Ok(false)`, and nothing written, where two of its message's
    /// signals share a name.
    pub fn write(&mut self, out: &mut impl std::io::Write, frame: &Frame) -> std::io::Result<bool> {
        let (id, extended) = frame
            .id()
            .map(|id| (id.as_raw(), id.is_extended()))
            .unwrap_or_default();
        let Some((index, _, decoded)) = self.dbc.decoder().decode_into(frame, &mut self.values)
        else {
            writeln!(
                out,
                r#"{{"error":"unknown message","extended":{extended},"id":{id},"name":null,"signals":{{}}}}"#
            )?;
            return Ok(true);
        };
        if let Some(pdus) = self.dbc.decoder().contained(index, frame.data()) {
            let name = self
                .dbc
                .decoder()
                .database()
                .messages
                .get(index)
                .map(bywire_dbc::Message::display_name);
            writeln!(out, "{}", container_json(id, extended, name, pdus))?;
            return Ok(true);
        }
        let Some(Some(message)) = self.messages.get(index) else {
            return Ok(false);
        };
        out.write_all(b"{")?;
        if let Err(error) = decoded {
            out.write_all(br#""error":"#)?;
            serde_json::to_writer(&mut *out, &error.to_string())?;
            out.write_all(b",")?;
        }
        out.write_all(if extended {
            br#""extended":true,"id":"#
        } else {
            br#""extended":false,"id":"#
        })?;
        serde_json::to_writer(&mut *out, &id)?;
        out.write_all(br#","name":"#)?;
        out.write_all(message.name.as_bytes())?;
        out.write_all(br#","signals":{"#)?;
        let mut first = true;
        for (signal, name) in &message.signals {
            let Some(Some(value)) = self.values.get(*signal) else {
                continue;
            };
            if !first {
                out.write_all(b",")?;
            }
            first = false;
            out.write_all(name.as_bytes())?;
            out.write_all(b":")?;
            match value.physical {
                Value::Int(i) => serde_json::to_writer(&mut *out, &i)?,
                Value::UInt(u) => serde_json::to_writer(&mut *out, &u)?,
                Value::Float(f) if f.is_finite() => serde_json::to_writer(&mut *out, &f)?,
                other => serde_json::to_writer(&mut *out, &json_number(other))?,
            }
        }
        out.write_all(b"}}\n")?;
        Ok(true)
    }
}

/// A container frame as JSON: the frame's object with its PDUs under `contained`, each with
/// its header ID, name (`null` when unknown), signals and any error; a frame that does not
/// split has the error.
fn container_json<'d>(
    id: u32,
    extended: bool,
    name: Option<&str>,
    pdus: impl Iterator<
        Item = Result<
            bywire_dbc::decoder::Contained<'d, 'd>,
            bywire_dbc::container::ContainerError,
        >,
    >,
) -> serde_json::Value {
    let mut contained = Vec::new();
    let mut error = None;
    for pdu in pdus {
        let pdu = match pdu {
            Ok(pdu) => pdu,
            Err(e) => {
                error = Some(e.to_string());
                break;
            }
        };
        let mut object = json!({"header_id": pdu.pdu.header_id, "name": null, "signals": {}});
        if let Some((message, codec, _)) = pdu.message {
            let mut values = vec![None; codec.signal_count()];
            let decoded = codec.decode(pdu.pdu.data, &mut values);
            let frame = DecodedFrame {
                message,
                signals: bywire_dbc::decoder::signal_values(message, &values).collect(),
                error: None,
            };
            object["name"] = json!(message.display_name());
            object["signals"] = serde_json::Value::Object(frame.json_signals());
            if let Err(e) = decoded {
                object["error"] = json!(e.to_string());
            }
        }
        contained.push(object);
    }
    let mut object = json!({"id": id, "extended": extended, "name": name, "signals": {}, "contained": contained});
    if let Some(e) = error {
        object["error"] = json!(e);
    }
    object
}

/// A value as JSON (non-finite floats as strings, which JSON has no number for).
pub fn json_number(v: Value) -> serde_json::Value {
    match v {
        Value::Int(i) => json!(i),
        Value::UInt(u) => json!(u),
        Value::Float(f) if f.is_nan() => json!("NaN"),
        Value::Float(f) if f.is_infinite() => json!(if f > 0.0 { "inf" } else { "-inf" }),
        Value::Float(f) => json!(f),
    }
}

/// Push a value as Python prints it (what cantools shows): integers plainly, floats as `repr`.
pub fn push_number_text(line: &mut String, v: Value) {
    match v {
        Value::Int(i) => line.push_str(itoa::Buffer::new().format(i)),
        Value::UInt(u) => line.push_str(itoa::Buffer::new().format(u)),
        Value::Float(f) => push_python_float(line, f),
    }
}

/// Python's `repr` of a float: the shortest digits that read back the same, in fixed notation
/// for decimal exponents -4 to 15 and as `1.5e+20` otherwise. One shortest-digits conversion
/// (ryu: the digits Python's repr finds too), laid out in place: no allocation.
fn push_python_float(line: &mut String, f: f64) {
    if f.is_nan() {
        return line.push_str("nan");
    }
    if f.is_infinite() {
        return line.push_str(if f > 0.0 { "inf" } else { "-inf" });
    }
    let mut buffer = ryu::Buffer::new();
    let text = buffer.format_finite(f);
    // From 1e-4 to 1e15 Python's digits stand in fixed notation, as ryu writes them when it
    // writes no exponent: the text as it is (most decoded values).
    if (1e-4..=1e15).contains(&f.abs()) && !text.as_bytes().contains(&b'e') {
        return line.push_str(text);
    }
    let (negative, text) = match text.strip_prefix('-') {
        Some(rest) => (true, rest),
        None => (false, text),
    };
    // ryu writes `123.45`, `1e16` or `1.5e-7`: its digits, and where the decimal point
    // falls among them (`point` digits before it), whatever notation it chose.
    let (mantissa, exponent) = match text.split_once('e') {
        Some((mantissa, exponent)) => (mantissa, exponent.parse::<i32>().unwrap_or(0)),
        None => (text, 0),
    };
    let (whole, fraction) = mantissa.split_once('.').unwrap_or((mantissa, ""));
    let mut digits = [0u8; 40];
    let mut count = 0usize;
    let mut point = i32::try_from(whole.len()).unwrap_or(0) + exponent;
    for &d in whole.as_bytes().iter().chain(fraction.as_bytes()) {
        if count == 0 && d == b'0' {
            point -= 1; // a leading zero: the point moves left of the first real digit
            continue;
        }
        if let Some(slot) = digits.get_mut(count) {
            *slot = d;
            count += 1;
        }
    }
    while count > 0 && digits.get(count - 1) == Some(&b'0') {
        count -= 1;
    }
    let digits = digits.get(..count).unwrap_or_default();
    if negative {
        line.push('-');
    }
    if digits.is_empty() {
        return line.push_str("0.0");
    }
    // The digits are ASCII: as text whole.
    let push_digits = |line: &mut String, d: &[u8]| {
        line.push_str(std::str::from_utf8(d).unwrap_or_default());
    };
    let decimal_exponent = point - 1;
    if (-4..16).contains(&decimal_exponent) {
        let split = usize::try_from(point).unwrap_or(0);
        if point <= 0 {
            line.push_str("0.");
            line.extend(std::iter::repeat_n(
                '0',
                usize::try_from(-point).unwrap_or(0),
            ));
            push_digits(line, digits);
        } else if split >= digits.len() {
            push_digits(line, digits);
            line.extend(std::iter::repeat_n('0', split - digits.len()));
            line.push_str(".0");
        } else {
            let (before, after) = digits.split_at(split);
            push_digits(line, before);
            line.push('.');
            push_digits(line, after);
        }
    } else {
        let (first, rest) = digits.split_at(1);
        push_digits(line, first);
        if !rest.is_empty() {
            line.push('.');
            push_digits(line, rest);
        }
        line.push_str(if decimal_exponent < 0 { "e-" } else { "e+" });
        let magnitude = decimal_exponent.unsigned_abs();
        if magnitude < 10 {
            line.push('0');
        }
        line.push_str(itoa::Buffer::new().format(magnitude));
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn floats_print_as_python_repr_does() {
        for (f, text) in [
            (0.0, "0.0"),
            (-0.0, "-0.0"),
            (1.5, "1.5"),
            (250.1, "250.1"),
            (1e16, "1e+16"),
            (1.5e20, "1.5e+20"),
            (123_456_789_012_345.6, "123456789012345.6"),
            (0.0001, "0.0001"),
            (0.00001, "1e-05"),
            (-2.5e-7, "-2.5e-07"),
            (1.561_586_132_418_2e36, "1.5615861324182e+36"),
            (f64::INFINITY, "inf"),
        ] {
            assert_eq!(python_float(f), text);
        }
    }

    fn python_float(f: f64) -> String {
        let mut text = String::new();
        super::push_python_float(&mut text, f);
        text
    }

    /// Python's own `repr` of 200,000 floats of every magnitude (random bit patterns, and
    /// decoded-looking values: integers times decimal scales), one per line from `python3`.
    #[test]
    fn floats_print_as_python_itself_prints_them() {
        use std::io::Write as _;
        let mut state = 0x9E37_79B9_7F4A_7C15u64;
        let mut floats = Vec::new();
        for i in 0..200_000u32 {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            let scale = [0.1, 0.01, 0.001, 0.5, 1e-6, 1e9][i as usize % 6];
            let f = if i % 2 == 0 {
                f64::from_bits(state)
            } else {
                (state % 100_000) as f64 * scale
            };
            if f.is_finite() {
                floats.push(f);
            }
        }
        let mut python = std::process::Command::new("python3")
            .args([
                "-c",
                "import struct,sys\nfor l in sys.stdin: print(repr(struct.unpack('<d', bytes.fromhex(l.strip()))[0]))",
            ])
            .stdin(std::process::Stdio::piped())
            .stdout(std::process::Stdio::piped())
            .spawn()
            .expect("python3 (installed on every machine the tests run on)");
        let mut input = python.stdin.take().unwrap();
        let hex: String = floats
            .iter()
            .map(|f| {
                f.to_le_bytes()
                    .iter()
                    .map(|b| format!("{b:02x}"))
                    .collect::<String>()
                    + "\n"
            })
            .collect();
        let writer = std::thread::spawn(move || input.write_all(hex.as_bytes()));
        let output = python.wait_with_output().unwrap();
        writer.join().unwrap().unwrap();
        let theirs = String::from_utf8(output.stdout).unwrap();
        let theirs: Vec<&str> = theirs.lines().collect();
        assert_eq!(theirs.len(), floats.len());
        for (f, text) in floats.iter().zip(theirs) {
            assert_eq!(python_float(*f), text, "{f:e}");
        }
    }

    /// The direct JSON line is byte for byte the `serde_json` object it stands in for: every
    /// message of a corpus DBC with random payloads, a short frame (an error), and an unknown
    /// identifier; a message whose signals share a name is left to the object's numbering.
    #[test]
    fn json_lines_are_the_objects_serde_json_writes() {
        use super::{Dbc, FrameText, JsonLines};
        use bywire_core::{Frame, Id};
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../../shared/corpus/dbc/opendbc/opendbc__dbc__ford_lincoln_base_pt.dbc"
        );
        let (db, _) =
            bywire_dbc::parse(&std::fs::read(path).unwrap(), bywire_dbc::Mode::Lenient).unwrap();
        let dbc = Dbc::new(db);
        let mut state = 0x2545_F491_4F6C_DD1Du64;
        let mut frames = Vec::new();
        for message in &dbc.decoder().database().messages {
            let id = if message.extended {
                Id::extended(message.id).unwrap()
            } else {
                Id::standard(message.id).unwrap()
            };
            let payload: Vec<u8> = (0..message.size)
                .map(|_| {
                    state ^= state << 13;
                    state ^= state >> 7;
                    state ^= state << 17;
                    state.to_le_bytes()[0]
                })
                .collect();
            let len = payload.len().min(8);
            frames.push(Frame::classic(id, &payload[..len]).unwrap());
            frames.push(Frame::classic(id, &payload[..len / 2]).unwrap());
        }
        frames.push(Frame::classic(Id::standard(0x7FF).unwrap(), &[1, 2]).unwrap());
        let mut lines = JsonLines::new(&dbc);
        for frame in &frames {
            let id = frame.id().unwrap();
            let decoded = dbc.decoder().decode(frame);
            let mut line = Vec::new();
            let written = lines.write(&mut line, frame).unwrap();
            assert!(written, "{frame}");
            let mut object = match &decoded {
                None => serde_json::json!({"id": id.as_raw(), "extended": id.is_extended(),
                    "name": null, "signals": {}, "error": "unknown message"}),
                Some(d) => serde_json::json!({"id": id.as_raw(), "extended": id.is_extended(),
                    "name": d.message.display_name(), "signals": d.json_signals()}),
            };
            if let Some(error) = decoded.as_ref().and_then(|d| d.error.as_ref()) {
                object["error"] = serde_json::json!(error);
            }
            assert_eq!(String::from_utf8(line).unwrap(), format!("{object}\n"));
        }
        // Two signals of one name: nothing written, the object's numbering applies.
        let text = "VERSION \"\"\nBU_: A\nBO_ 256 M: 2 A\n SG_ S : 0|8@1+ (1,0) [0|255] \"\" A\n SG_ S : 8|8@1+ (1,0) [0|255] \"\" A\n";
        let (db, _) = bywire_dbc::parse(text.as_bytes(), bywire_dbc::Mode::Lenient).unwrap();
        let dbc = Dbc::new(db);
        let frame = Frame::classic(Id::standard(0x100).unwrap(), &[1, 2]).unwrap();
        let mut line = Vec::new();
        assert!(!JsonLines::new(&dbc).write(&mut line, &frame).unwrap());
        assert!(line.is_empty());
    }
}
