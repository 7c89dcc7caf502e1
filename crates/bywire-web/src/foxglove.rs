//! The Foxglove WebSocket protocol (`foxglove.websocket.v1`), server side, without I/O: the
//! messages a server sends (server info, channel advertisements, status, message data) and
//! the client messages it reads (subscribe, unsubscribe, client channels and what they
//! publish). Foxglove's app, its `@foxglove/ws-protocol` client and SDKs speak it, and so does
//! bywire's own page.
//!
//! Written here rather than taken from the Foxglove SDK crate: the SDK brings an async runtime
//! and a server of its own, while bywire's server must share one port with its page, bound
//! every client's queue and keep the same token rules as `serve`; the protocol is a handful of
//! JSON messages and one binary frame layout.

use serde::{Deserialize, Serialize};

/// The WebSocket subprotocol.
pub const SUBPROTOCOL: &str = "foxglove.websocket.v1";

/// Binary opcode of a server's message data.
const MESSAGE_DATA: u8 = 1;
/// Binary opcode of a client's published message.
const CLIENT_MESSAGE_DATA: u8 = 1;

/// Most subscriptions, or client channels, one message may carry (more are refused).
pub const MAX_ITEMS: usize = 4096;

/// A channel as advertised.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "camelCase")]
pub struct Channel {
    /// Its identifier.
    pub id: u32,
    /// Its topic (`/bus1/frames`, `/bus1/EngineData`).
    pub topic: String,
    /// The messages' encoding (`json`).
    pub encoding: String,
    /// The schema's name.
    pub schema_name: String,
    /// The schema itself (a JSON Schema as text).
    pub schema: String,
    /// The schema's encoding (`jsonschema`).
    pub schema_encoding: String,
}

impl Channel {
    /// A channel of JSON messages described by a JSON Schema.
    pub fn json(id: u32, topic: String, schema_name: &str, schema: &serde_json::Value) -> Self {
        Channel {
            id,
            topic,
            encoding: "json".into(),
            schema_name: schema_name.into(),
            schema: schema.to_string(),
            schema_encoding: "jsonschema".into(),
        }
    }
}

/// A status message's level.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Level {
    /// Information.
    Info = 0,
    /// A warning.
    Warning = 1,
    /// An error.
    Error = 2,
}

/// The server's first message: its name, what it can do and what it says of itself.
pub fn server_info(
    name: &str,
    capabilities: &[&str],
    metadata: &serde_json::Map<String, serde_json::Value>,
    session_id: &str,
) -> String {
    serde_json::json!({
        "op": "serverInfo",
        "name": name,
        "capabilities": capabilities,
        "supportedEncodings": ["json"],
        "metadata": metadata,
        "sessionId": session_id,
    })
    .to_string()
}

/// The channels a client may subscribe to.
pub fn advertise(channels: &[Channel]) -> String {
    serde_json::json!({"op": "advertise", "channels": channels}).to_string()
}

/// A status message (shown by Foxglove's app in its problems list).
pub fn status(level: Level, message: &str) -> String {
    serde_json::json!({"op": "status", "level": level as u8, "message": message}).to_string()
}

/// One message on a subscription: opcode, subscription, log time (ns), payload.
pub fn message_data(subscription: u32, log_time: u64, payload: &[u8]) -> Vec<u8> {
    let mut data = Vec::with_capacity(13 + payload.len());
    data.push(MESSAGE_DATA);
    data.extend_from_slice(&subscription.to_le_bytes());
    data.extend_from_slice(&log_time.to_le_bytes());
    data.extend_from_slice(payload);
    data
}

/// A client's channel (what it will publish).
#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct ClientChannel {
    /// The client's identifier for it.
    pub id: u32,
    /// Its topic.
    pub topic: String,
    /// The encoding of what it publishes.
    pub encoding: String,
    /// Its schema's name.
    #[serde(default)]
    pub schema_name: String,
}

/// A subscription a client asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Subscription {
    /// The client's identifier for it.
    pub id: u32,
    /// The channel.
    pub channel_id: u32,
}

/// A message from a client.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ClientMessage<'a> {
    /// Subscribe to channels.
    Subscribe(Vec<Subscription>),
    /// End subscriptions.
    Unsubscribe(Vec<u32>),
    /// Channels the client will publish on.
    Advertise(Vec<ClientChannel>),
    /// Client channels it closes.
    Unadvertise(Vec<u32>),
    /// A message on one of its channels.
    Publish {
        /// The client channel.
        channel: u32,
        /// The message.
        data: &'a [u8],
    },
    /// An operation this server does not offer (named for the status it answers with).
    Unsupported(String),
}

/// Why a client message cannot be read.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ProtocolError {
    /// Not JSON, or not the shape its operation has.
    #[error("a message that is not the protocol's: {0}")]
    Malformed(String),
    /// More items than [`MAX_ITEMS`].
    #[error("more than {MAX_ITEMS} items in one message")]
    TooMany,
}

#[derive(Deserialize)]
#[serde(tag = "op", rename_all = "camelCase")]
enum Text {
    Subscribe {
        subscriptions: Vec<Subscription>,
    },
    Unsubscribe {
        #[serde(rename = "subscriptionIds")]
        subscription_ids: Vec<u32>,
    },
    Advertise {
        channels: Vec<ClientChannel>,
    },
    Unadvertise {
        #[serde(rename = "channelIds")]
        channel_ids: Vec<u32>,
    },
}

#[derive(Deserialize)]
struct Op {
    op: String,
}

/// Read a client's text message.
pub fn parse_text(text: &str) -> Result<ClientMessage<'static>, ProtocolError> {
    let op: Op = serde_json::from_str(text).map_err(|e| ProtocolError::Malformed(e.to_string()))?;
    if !matches!(
        op.op.as_str(),
        "subscribe" | "unsubscribe" | "advertise" | "unadvertise"
    ) {
        return Ok(ClientMessage::Unsupported(op.op));
    }
    let message: Text =
        serde_json::from_str(text).map_err(|e| ProtocolError::Malformed(e.to_string()))?;
    let (count, message) = match message {
        Text::Subscribe { subscriptions } => {
            (subscriptions.len(), ClientMessage::Subscribe(subscriptions))
        }
        Text::Unsubscribe { subscription_ids } => (
            subscription_ids.len(),
            ClientMessage::Unsubscribe(subscription_ids),
        ),
        Text::Advertise { channels } => (channels.len(), ClientMessage::Advertise(channels)),
        Text::Unadvertise { channel_ids } => {
            (channel_ids.len(), ClientMessage::Unadvertise(channel_ids))
        }
    };
    if count > MAX_ITEMS {
        return Err(ProtocolError::TooMany);
    }
    Ok(message)
}

/// Read a client's binary message (a message published on one of its channels).
pub fn parse_binary(data: &[u8]) -> Result<ClientMessage<'_>, ProtocolError> {
    match data {
        [CLIENT_MESSAGE_DATA, a, b, c, d, rest @ ..] => Ok(ClientMessage::Publish {
            channel: u32::from_le_bytes([*a, *b, *c, *d]),
            data: rest,
        }),
        [CLIENT_MESSAGE_DATA, ..] => Err(ProtocolError::Malformed(
            "a published message shorter than its header".into(),
        )),
        [op, ..] => Ok(ClientMessage::Unsupported(format!("binary opcode {op}"))),
        [] => Err(ProtocolError::Malformed("an empty binary message".into())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn client_messages_read_as_the_protocol_writes_them() {
        assert_eq!(
            parse_text(r#"{"op":"subscribe","subscriptions":[{"id":7,"channelId":2}]}"#),
            Ok(ClientMessage::Subscribe(vec![Subscription {
                id: 7,
                channel_id: 2
            }]))
        );
        assert_eq!(
            parse_text(r#"{"op":"unsubscribe","subscriptionIds":[7]}"#),
            Ok(ClientMessage::Unsubscribe(vec![7]))
        );
        assert_eq!(
            parse_text(
                r#"{"op":"advertise","channels":[{"id":1,"topic":"/bus1/frames","encoding":"json","schemaName":"bywire.CanFrame"}]}"#
            ),
            Ok(ClientMessage::Advertise(vec![ClientChannel {
                id: 1,
                topic: "/bus1/frames".into(),
                encoding: "json".into(),
                schema_name: "bywire.CanFrame".into(),
            }]))
        );
        assert_eq!(
            parse_text(r#"{"op":"getParameters","parameterNames":[]}"#),
            Ok(ClientMessage::Unsupported("getParameters".into()))
        );
        assert!(matches!(
            parse_text(r#"{"op":"subscribe","subscriptions":[{"id":-1}]}"#),
            Err(ProtocolError::Malformed(_))
        ));
        assert!(matches!(
            parse_text("not json"),
            Err(ProtocolError::Malformed(_))
        ));
        let many = format!(
            r#"{{"op":"unsubscribe","subscriptionIds":[{}]}}"#,
            vec!["1"; MAX_ITEMS + 1].join(",")
        );
        assert_eq!(parse_text(&many), Err(ProtocolError::TooMany));
        assert_eq!(
            parse_binary(&[1, 3, 0, 0, 0, b'{', b'}']),
            Ok(ClientMessage::Publish {
                channel: 3,
                data: b"{}"
            })
        );
        assert!(parse_binary(&[1, 3]).is_err());
        assert!(parse_binary(&[]).is_err());
    }

    #[test]
    fn message_data_is_opcode_subscription_time_payload() {
        assert_eq!(
            message_data(2, 0x0102_0304_0506_0708, b"x"),
            [1, 2, 0, 0, 0, 8, 7, 6, 5, 4, 3, 2, 1, b'x']
        );
    }
}
