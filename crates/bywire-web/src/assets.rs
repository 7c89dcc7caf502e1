//! The page's files, embedded in the binary, and the database as the page reads it.

use serde_json::{json, Value as Json};

use bywire_dbc::decoder::Decoder;

use crate::hub::Hub;
use crate::logs::Logs;

const INDEX: &str = include_str!("../assets/index.html");
const APP_JS: &str = include_str!("../assets/app.js");
const APP_CSS: &str = include_str!("../assets/app.css");
const UPLOT_JS: &str = include_str!("../assets/vendor/uPlot.iife.min.js");
const UPLOT_CSS: &str = include_str!("../assets/vendor/uPlot.min.css");
const UPLOT_LICENSE: &str = include_str!("../assets/vendor/LICENSE.uPlot");

/// The file at `path`: its content type and bytes.
pub fn asset(path: &str) -> Option<(&'static str, &'static [u8])> {
    let (kind, text) = match path {
        "/" | "/index.html" => ("text/html; charset=utf-8", INDEX),
        "/app.js" => ("text/javascript; charset=utf-8", APP_JS),
        "/app.css" => ("text/css; charset=utf-8", APP_CSS),
        "/vendor/uPlot.iife.min.js" => ("text/javascript; charset=utf-8", UPLOT_JS),
        "/vendor/uPlot.min.css" => ("text/css; charset=utf-8", UPLOT_CSS),
        "/vendor/LICENSE.uPlot" => ("text/plain; charset=utf-8", UPLOT_LICENSE),
        _ => return None,
    };
    Some((kind, text.as_bytes()))
}

/// The buses, each with its database's messages and signals (each signal by the name its
/// decoded channel gives it, with unit, range and value names), for the page's tree and its
/// transmit panel.
pub fn database_json(hub: &Hub, logs: &Logs) -> Json {
    let buses: Vec<Json> = hub
        .buses()
        .map(|(name, decoder)| json!({"name": name, "messages": decoder.map_or_else(Vec::new, messages_json)}))
        .collect();
    let logs = (!logs.is_empty())
        .then(|| logs.database())
        .flatten()
        .map(|d| json!({"messages": messages_json(d.decoder())}));
    json!({ "buses": buses, "logs": logs })
}

fn messages_json(decoder: &Decoder) -> Vec<Json> {
    (0..decoder.message_count())
        .filter_map(|i| decoder.message_at(i))
        .map(|(message, _)| {
            let names = bywire_dbc::decoder::field_names(message);
            let signals: Vec<Json> = message
                .signals
                .iter()
                .zip(&names)
                .map(|(s, name)| {
                    let choices: Vec<Json> = s
                        .value_descriptions
                        .iter()
                        .map(|(value, label)| json!([value.to_string(), label]))
                        .collect();
                    json!({
                        "name": name,
                        "unit": s.unit,
                        "minimum": s.minimum.as_f64(),
                        "maximum": s.maximum.as_f64(),
                        "choices": choices,
                        "comment": s.comment,
                    })
                })
                .collect();
            let cycle = decoder
                .database()
                .cycle_time(message)
                .map(|d| d.as_secs_f64() * 1e3);
            json!({
                "name": message.display_name(),
                "id": message.id,
                "extended": message.extended,
                "size": message.size,
                "cycle_ms": cycle,
                "signals": signals,
            })
        })
        .collect()
}
