//! A message's decoded values as a JSON object, and the JSON Schema of that object: what
//! MCAP's decoded channels and the live Foxglove channels carry. Each signal is a property
//! named by [`field_names`] (its value exact for integers, `null` for a non-finite float), and a
//! signal with value names has a `NAME_choice` property beside it (`null` when its value has
//! no name).

use crate::codec::{whole_scaling, Decoded, Value};
use crate::decoder::{field_names, SignalValue};
use crate::Message;

/// How one message's decoded values are written as JSON: its properties' names, worked out
/// once.
#[derive(Debug, Clone)]
pub struct MessageJson {
    names: Vec<String>,
}

impl MessageJson {
    /// The JSON form of `message`'s values.
    pub fn new(message: &Message) -> Self {
        MessageJson {
            names: field_names(message),
        }
    }

    /// The properties' names, in signal order.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// The decoded `values` of `message` (in signal order, `None` for a signal its
    /// multiplexer left out) as a JSON object.
    pub fn object(
        &self,
        message: &Message,
        values: &[Option<Decoded>],
    ) -> serde_json::Map<String, serde_json::Value> {
        let mut object = serde_json::Map::new();
        for ((signal, name), value) in message.signals.iter().zip(&self.names).zip(values) {
            let Some(value) = value else { continue };
            object.insert(name.clone(), value_json(value.physical));
            if !signal.value_descriptions.is_empty() {
                let text = SignalValue {
                    signal,
                    value: *value,
                }
                .description()
                .map_or(serde_json::Value::Null, |d| d.into());
                object.insert(format!("{name}_choice"), text);
            }
        }
        object
    }

    /// The JSON Schema of `message`'s objects.
    pub fn schema(&self, message: &Message) -> serde_json::Value {
        let mut properties = serde_json::Map::new();
        for (signal, name) in message.signals.iter().zip(&self.names) {
            let mut property = serde_json::Map::new();
            let kind = if whole_scaling(signal).is_some() {
                serde_json::json!("integer")
            } else {
                serde_json::json!(["number", "null"])
            };
            property.insert("type".into(), kind);
            let description = match (&signal.comment, signal.unit.is_empty()) {
                (Some(comment), _) => Some(comment.clone()),
                (None, false) => Some(format!("[{}]", signal.unit)),
                (None, true) => None,
            };
            if let Some(description) = description {
                property.insert("description".into(), description.into());
            }
            properties.insert(name.clone(), property.into());
            if !signal.value_descriptions.is_empty() {
                let labels = signal
                    .value_descriptions
                    .iter()
                    .map(|(_, label)| serde_json::Value::from(label.as_str()))
                    .chain([serde_json::Value::Null]);
                properties.insert(
                    format!("{name}_choice"),
                    serde_json::json!({"type": ["string", "null"], "enum": labels.collect::<Vec<_>>()}),
                );
            }
        }
        serde_json::json!({
            "$schema": "https://json-schema.org/draft/2020-12/schema",
            "title": message.display_name(),
            "type": "object",
            "properties": properties,
            "additionalProperties": false,
        })
    }
}

/// A physical value as JSON: integers exact, non-finite floats `null` (JSON has no number for
/// them).
pub fn value_json(value: Value) -> serde_json::Value {
    match value {
        Value::Int(i) => i.into(),
        Value::UInt(u) => u.into(),
        Value::Float(f) => {
            serde_json::Number::from_f64(f).map_or(serde_json::Value::Null, Into::into)
        }
    }
}
