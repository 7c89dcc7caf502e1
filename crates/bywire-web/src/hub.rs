//! The hub between buses and WebSocket clients: it turns each frame into the channels'
//! messages (raw, and decoded when a database knows the frame), counts every frame for each
//! bus's statistics, and hands each client the messages it subscribed to through a bounded
//! queue — a slow client loses messages (counted and told), never stalls a bus or another
//! client. What clients publish becomes frames on a bus, when sending is allowed.
//!
//! Channels per bus: `/BUS/frames` (every frame), `/BUS/stats` (once a second), `/BUS/batch`
//! (every frame of the last 50 ms with its decoded signals, in one message: for viewers that
//! draw at their own pace, as the page does — a message per frame costs a browser more than
//! the frame) and `/BUS/MESSAGE` for each message of the database (as the MCAP decoded
//! channels); more channels (the simulated tug's pose) can be added before the hub starts.

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, SyncSender, TrySendError};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use bywire_bus::{BusError, BusRx, BusTx, Received};
use bywire_core::busload::{frame_bits, Stuffing};
use bywire_core::frame::FdFrame;
use bywire_core::{Frame, Id, Timestamp};
use bywire_dbc::codec::{Decoded, EncodeMode};
use bywire_dbc::decoder::Decoder;
use bywire_dbc::json::MessageJson;
use bywire_dbc::named::{encode_named, Encoding, Given, Named};
use serde_json::{json, Map, Value as Json};

use crate::foxglove::{self, Channel, ClientChannel, ClientMessage, Level};

/// Messages waiting for one client; past this, its messages are dropped.
pub const CLIENT_QUEUE: usize = 8192;
/// Clients at once.
pub const MAX_CLIENTS: usize = 32;
/// Channels one client may publish on.
const MAX_CLIENT_CHANNELS: usize = 256;
/// Channels in all (buses × messages and added ones).
const MAX_CHANNELS: usize = 1 << 20;
/// Within a bus's channels: the batches, and the first message's.
const BATCH: usize = 2;
const FIRST_MESSAGE: usize = 3;
/// Frames one batch holds; more before it is sent are left out of it (and counted).
const MAX_BATCH: usize = 20_000;

/// A message for a client's socket.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Outgoing {
    /// A text message (JSON).
    Text(String),
    /// A binary message.
    Binary(Vec<u8>),
}

/// One bus's counts, updated by its reader and read by the ticker.
#[derive(Default)]
struct Counters {
    frames: AtomicU64,
    errors: AtomicU64,
    bits: AtomicU64,
    dropped: AtomicU64,
    closed: AtomicBool,
    /// The controller's state as its error frames last said it ([`STATES`]; 0: not said).
    state: std::sync::atomic::AtomicU8,
    /// Its error counters as its error frames last gave them (transmit << 8 | receive; and
    /// whether any did, in bit 16).
    counters: AtomicU32,
    /// Frames left out of a full batch.
    unbatched: AtomicU64,
}

/// Controller states, as SocketCAN's error frames tell them.
const STATES: [&str; 5] = [
    "",
    "error-active",
    "error-warning",
    "error-passive",
    "bus-off",
];

/// The controller state an error frame tells, if it tells one.
fn state_told(error: &bywire_core::frame::ErrorFrame) -> Option<u8> {
    use bywire_core::frame::ErrorClass;
    let problems = error.data().get(1).copied().unwrap_or(0);
    if error.has(ErrorClass::BusOff) {
        Some(4)
    } else if error.has(ErrorClass::Restarted) {
        Some(1)
    } else if error.has(ErrorClass::Controller) {
        match problems {
            p if p & 0x30 != 0 => Some(3),
            p if p & 0x0C != 0 => Some(2),
            p if p & 0x40 != 0 => Some(1),
            _ => None,
        }
    } else {
        None
    }
}

struct BusSlot {
    name: String,
    tx: Option<Mutex<Box<dyn BusTx>>>,
    bitrate: Option<u32>,
    counters: Counters,
    /// The bus's database (buses may share one).
    database: Option<Arc<Database>>,
    /// Its first channel's index: raw frames, then statistics, batches, a channel per message.
    base: usize,
    /// The frames of the batch being gathered.
    batch: Mutex<Vec<Json>>,
}

/// A database compiled for decoding, with each message's JSON form.
pub struct Database {
    decoder: Decoder,
    json: Vec<MessageJson>,
}

impl Database {
    /// `decoder`, with its messages' JSON forms worked out once.
    pub fn new(decoder: Decoder) -> Self {
        let json = (0..decoder.message_count())
            .filter_map(|i| decoder.message_at(i))
            .map(|(message, _)| MessageJson::new(message))
            .collect();
        Database { decoder, json }
    }

    /// The decoder.
    pub fn decoder(&self) -> &Decoder {
        &self.decoder
    }

    fn messages(&self) -> usize {
        self.json.len()
    }

    /// Message `index`'s decoded `values` (in the decoder's numbering) as a JSON object.
    pub fn object(
        &self,
        index: usize,
        message: &bywire_dbc::Message,
        values: &[Option<Decoded>],
    ) -> Option<Map<String, Json>> {
        Some(self.json.get(index)?.object(message, values))
    }
}

impl BusSlot {
    /// How many channels it has.
    fn channels(&self) -> usize {
        FIRST_MESSAGE + self.database.as_ref().map_or(0, |d| d.messages())
    }
}

/// Where a client channel's messages go.
#[derive(Debug, Clone, Copy)]
enum Target {
    /// The hub's owner (a command topic, by its index: the simulated tug's fault buttons).
    Inbox { topic: usize },
    /// Raw frames (`/BUS/frames`).
    Frames { bus: usize },
    /// A message by its signals (`/BUS/MESSAGE`), its counter counting up.
    Message {
        bus: usize,
        message: usize,
        counter: u64,
    },
}

struct Client {
    id: u64,
    queue: SyncSender<Outgoing>,
    /// Channel to the client's subscription identifier.
    subscriptions: HashMap<u32, u32>,
    /// What the client publishes on.
    publishing: HashMap<u32, Target>,
    can_send: bool,
    dropped: u64,
    told_dropped: u64,
}

impl Client {
    fn push(&mut self, message: Outgoing) {
        match self.queue.try_send(message) {
            Ok(()) | Err(TrySendError::Disconnected(_)) => {}
            Err(TrySendError::Full(_)) => self.dropped += 1,
        }
    }
}

/// What a hub is made of: its buses, its database, channels of its own.
pub struct HubBuilder {
    name: String,
    buses: Vec<BusSlot>,
    extra: Vec<(String, String, Json)>,
    commands: Vec<String>,
    metadata: Map<String, Json>,
}

/// Commands clients published on command topics, waiting for the hub's owner; past this,
/// more are refused.
const MAX_INBOX: usize = 256;

impl HubBuilder {
    /// A hub the clients know as `name`.
    pub fn new(name: &str) -> Self {
        HubBuilder {
            name: name.into(),
            buses: Vec::new(),
            extra: Vec::new(),
            commands: Vec::new(),
            metadata: Map::new(),
        }
    }

    /// A topic clients may publish JSON objects on for the hub's owner to take
    /// ([`Hub::take_commands`]), when they may send.
    pub fn command_topic(mut self, topic: &str) -> Self {
        self.commands.push(topic.into());
        self
    }

    /// Add a bus: its name, the half that sends (when clients may send on it), its bitrate
    /// (for the load) and the database its frames are decoded with. Its index is the order of
    /// adding.
    pub fn bus(
        mut self,
        name: &str,
        tx: Option<Box<dyn BusTx>>,
        bitrate: Option<u32>,
        database: Option<Arc<Database>>,
    ) -> Self {
        self.buses.push(BusSlot {
            name: name.into(),
            tx: tx.map(Mutex::new),
            bitrate,
            counters: Counters::default(),
            database,
            base: 0,
            batch: Mutex::new(Vec::new()),
        });
        self
    }

    /// A channel of JSON messages of the caller's (published by [`Hub::publish_json`] with
    /// the index returned by [`Hub::extra_channel`]).
    pub fn channel(mut self, topic: &str, schema_name: &str, schema: Json) -> Self {
        self.extra.push((topic.into(), schema_name.into(), schema));
        self
    }

    /// Something the server says of itself (shown by Foxglove's app).
    pub fn metadata(mut self, key: &str, value: &str) -> Self {
        self.metadata.insert(key.into(), value.into());
        self
    }

    /// The hub.
    pub fn build(mut self) -> Result<Arc<Hub>, String> {
        let total = self
            .buses
            .iter()
            .map(BusSlot::channels)
            .fold(self.extra.len(), usize::saturating_add);
        if total > MAX_CHANNELS {
            return Err(format!(
                "{total} channels ({} buses and their messages): at most {MAX_CHANNELS}",
                self.buses.len()
            ));
        }
        let mut channels = Vec::with_capacity(total);
        for bus in &mut self.buses {
            bus.base = channels.len();
            channels.push(Channel::json(
                next_id(&channels),
                format!("/{}/frames", bus.name),
                "bywire.CanFrame",
                &frame_schema(),
            ));
            channels.push(Channel::json(
                next_id(&channels),
                format!("/{}/stats", bus.name),
                "bywire.BusStats",
                &stats_schema(),
            ));
            channels.push(Channel::json(
                next_id(&channels),
                format!("/{}/batch", bus.name),
                "bywire.CanFrames",
                &batch_schema(),
            ));
            if let Some(database) = &bus.database {
                for (index, json) in database.json.iter().enumerate() {
                    if let Some((message, _)) = database.decoder.message_at(index) {
                        channels.push(Channel::json(
                            next_id(&channels),
                            format!("/{}/{}", bus.name, message.display_name()),
                            message.display_name(),
                            &json.schema(message),
                        ));
                    }
                }
            }
        }
        let extra_base = channels.len();
        for (topic, schema_name, schema) in &self.extra {
            channels.push(Channel::json(
                next_id(&channels),
                topic.clone(),
                schema_name,
                schema,
            ));
        }
        let subscribers = (0..channels.len()).map(|_| AtomicU32::new(0)).collect();
        Ok(Arc::new(Hub {
            name: self.name,
            metadata: self.metadata,
            buses: self.buses,
            extra_base,
            channels,
            subscribers,
            commands: self.commands,
            inbox: Mutex::new(Vec::new()),
            clients: Mutex::new(Vec::new()),
            next_client: AtomicU64::new(1),
        }))
    }
}

/// Channel identifiers are their index plus one (0 is no channel in some clients).
fn next_id(channels: &[Channel]) -> u32 {
    u32::try_from(channels.len() + 1).unwrap_or(u32::MAX)
}

/// The hub (shared by the buses' readers, the ticker and the clients' sessions).
pub struct Hub {
    name: String,
    metadata: Map<String, Json>,
    buses: Vec<BusSlot>,
    extra_base: usize,
    channels: Vec<Channel>,
    /// Subscribers per channel (by index), so nobody's channel costs nothing.
    subscribers: Vec<AtomicU32>,
    commands: Vec<String>,
    inbox: Mutex<Vec<(String, Map<String, Json>)>>,
    clients: Mutex<Vec<Client>>,
    next_client: AtomicU64,
}

/// A client's end of the hub.
pub struct Session {
    /// The client's identifier in the hub.
    pub id: u64,
    /// Its messages, in order.
    pub queue: Receiver<Outgoing>,
}

impl Hub {
    fn clients(&self) -> MutexGuard<'_, Vec<Client>> {
        self.clients
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// The advertised channels.
    pub fn channels(&self) -> &[Channel] {
        &self.channels
    }

    /// The buses: each one's name and database.
    pub fn buses(&self) -> impl Iterator<Item = (&str, Option<&Decoder>)> {
        self.buses
            .iter()
            .map(|b| (b.name.as_str(), b.database.as_ref().map(|d| d.decoder())))
    }

    /// Whether a client may send on bus `bus`.
    fn can_send_on(&self, bus: usize) -> bool {
        self.buses.get(bus).is_some_and(|b| b.tx.is_some())
    }

    /// Whether any bus takes frames from clients.
    pub fn sends(&self) -> bool {
        self.buses.iter().any(|b| b.tx.is_some())
    }

    /// A new client: its session, its first messages queued (server info and the channels).
    /// `None` when [`MAX_CLIENTS`] are connected. `can_send`: whether it may publish.
    pub fn connect(&self, can_send: bool) -> Option<Session> {
        let mut clients = self.clients();
        if clients.len() >= MAX_CLIENTS {
            return None;
        }
        let id = self.next_client.fetch_add(1, Ordering::Relaxed);
        let (queue, receiver) = sync_channel(CLIENT_QUEUE);
        let can_send = can_send && self.sends();
        let capabilities: &[&str] = if can_send { &["clientPublish"] } else { &[] };
        let mut client = Client {
            id,
            queue,
            subscriptions: HashMap::new(),
            publishing: HashMap::new(),
            can_send,
            dropped: 0,
            told_dropped: 0,
        };
        client.push(Outgoing::Text(foxglove::server_info(
            &self.name,
            capabilities,
            &self.metadata,
            &id.to_string(),
        )));
        client.push(Outgoing::Text(foxglove::advertise(&self.channels)));
        clients.push(client);
        Some(Session {
            id,
            queue: receiver,
        })
    }

    /// A client has gone: its subscriptions end.
    pub fn disconnect(&self, id: u64) {
        let mut clients = self.clients();
        if let Some(at) = clients.iter().position(|c| c.id == id) {
            let client = clients.swap_remove(at);
            for channel in client.subscriptions.keys() {
                self.count_subscriber(*channel, false);
            }
        }
    }

    fn channel_index(&self, channel: u32) -> Option<usize> {
        let index = usize::try_from(channel).ok()?.checked_sub(1)?;
        (index < self.channels.len()).then_some(index)
    }

    fn count_subscriber(&self, channel: u32, more: bool) {
        if let Some(count) = self
            .channel_index(channel)
            .and_then(|i| self.subscribers.get(i))
        {
            if more {
                count.fetch_add(1, Ordering::Relaxed);
            } else {
                let _ =
                    count.fetch_update(Ordering::Relaxed, Ordering::Relaxed, |n| n.checked_sub(1));
            }
        }
    }

    fn subscribed(&self, index: usize) -> bool {
        self.subscribers
            .get(index)
            .is_some_and(|n| n.load(Ordering::Relaxed) > 0)
    }

    /// A message from client `id`: answered, when it needs an answer, on its queue.
    pub fn handle(&self, id: u64, message: ClientMessage<'_>) {
        let mut clients = self.clients();
        let Some(client) = clients.iter_mut().find(|c| c.id == id) else {
            return;
        };
        match message {
            ClientMessage::Subscribe(subscriptions) => {
                for s in subscriptions {
                    if self.channel_index(s.channel_id).is_none() {
                        client.push(Outgoing::Text(foxglove::status(
                            Level::Warning,
                            &format!("no channel {}", s.channel_id),
                        )));
                        continue;
                    }
                    if client.subscriptions.insert(s.channel_id, s.id).is_none() {
                        self.count_subscriber(s.channel_id, true);
                    }
                }
            }
            ClientMessage::Unsubscribe(ids) => {
                let channels: Vec<u32> = client
                    .subscriptions
                    .iter()
                    .filter(|(_, sub)| ids.contains(sub))
                    .map(|(channel, _)| *channel)
                    .collect();
                for channel in channels {
                    client.subscriptions.remove(&channel);
                    self.count_subscriber(channel, false);
                }
            }
            ClientMessage::Advertise(channels) => {
                for channel in channels {
                    let answer = self.advertised(client, &channel);
                    if let Err(problem) = answer {
                        client.push(Outgoing::Text(foxglove::status(Level::Error, &problem)));
                    }
                }
            }
            ClientMessage::Unadvertise(ids) => {
                for id in ids {
                    client.publishing.remove(&id);
                }
            }
            ClientMessage::Publish { channel, data } => {
                let target = client.publishing.get_mut(&channel);
                let result = match target {
                    None => Err(format!("message on channel {channel}, never advertised")),
                    Some(target) => self.publish_from_client(target, data),
                };
                if let Err(problem) = result {
                    client.push(Outgoing::Text(foxglove::status(Level::Error, &problem)));
                }
            }
            ClientMessage::Unsupported(op) => {
                client.push(Outgoing::Text(foxglove::status(
                    Level::Warning,
                    &format!("'{op}' is not offered by this server"),
                )));
            }
        }
    }

    /// A client's channel, checked: what it publishes on and whether it may.
    fn advertised(&self, client: &mut Client, channel: &ClientChannel) -> Result<(), String> {
        if !client.can_send {
            return Err(format!(
                "{}: this server does not take frames from clients (start it with --allow-send)",
                channel.topic
            ));
        }
        if channel.encoding != "json" {
            return Err(format!(
                "{}: encoding '{}' (this server takes json)",
                channel.topic, channel.encoding
            ));
        }
        if client.publishing.len() >= MAX_CLIENT_CHANNELS {
            return Err(format!("more than {MAX_CLIENT_CHANNELS} client channels"));
        }
        if let Some(topic) = self.commands.iter().position(|t| *t == channel.topic) {
            client
                .publishing
                .insert(channel.id, Target::Inbox { topic });
            return Ok(());
        }
        let index = self
            .channels
            .iter()
            .take(self.extra_base)
            .position(|c| c.topic == channel.topic)
            .ok_or_else(|| format!("{}: no such channel to send on", channel.topic))?;
        let bus = self
            .buses
            .iter()
            .rposition(|b| b.base <= index)
            .ok_or("no bus")?;
        let within = index - self.buses.get(bus).map_or(0, |b| b.base);
        if !self.can_send_on(bus) {
            return Err(format!("{}: its bus does not take frames", channel.topic));
        }
        let target = match within {
            0 => Target::Frames { bus },
            n if n < FIRST_MESSAGE => {
                return Err(format!("{}: not a channel to send on", channel.topic))
            }
            n => Target::Message {
                bus,
                message: n - FIRST_MESSAGE,
                counter: 0,
            },
        };
        client.publishing.insert(channel.id, target);
        Ok(())
    }

    /// What a client published: the frame it describes, sent on its bus.
    fn publish_from_client(&self, target: &mut Target, data: &[u8]) -> Result<(), String> {
        let object: Map<String, Json> = serde_json::from_slice(data)
            .map_err(|e| format!("a published message that is not a JSON object: {e}"))?;
        let (bus, frame) = match target {
            Target::Inbox { topic } => return self.to_inbox(*topic, object),
            Target::Frames { bus } => (*bus, frame_from_json(&object)?),
            Target::Message {
                bus,
                message,
                counter,
            } => {
                let frame = self.encode(*bus, *message, &object, *counter)?;
                *counter = counter.wrapping_add(1);
                (*bus, frame)
            }
        };
        let slot = self.buses.get(bus).ok_or("no such bus")?;
        let tx = slot.tx.as_ref().ok_or("this bus does not take frames")?;
        let mut tx = tx.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        tx.send(&frame)
            .map_err(|e| format!("sending {frame} on {}: {e}", slot.name))
    }

    fn to_inbox(&self, topic: usize, object: Map<String, Json>) -> Result<(), String> {
        let mut inbox = self
            .inbox
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if inbox.len() >= MAX_INBOX {
            return Err(format!("more than {MAX_INBOX} commands waiting: refused"));
        }
        let topic = self.commands.get(topic).cloned().unwrap_or_default();
        inbox.push((topic, object));
        Ok(())
    }

    /// The commands clients published since the last call, in order.
    pub fn take_commands(&self) -> Vec<(String, Map<String, Json>)> {
        std::mem::take(
            &mut *self
                .inbox
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner),
        )
    }

    /// A message's frame from its signals' values (names as in the database, numbers or value
    /// names), its counter and checksum filled in as the database declares them.
    fn encode(
        &self,
        bus: usize,
        index: usize,
        object: &Map<String, Json>,
        counter: u64,
    ) -> Result<Frame, String> {
        let decoder = self
            .buses
            .get(bus)
            .and_then(|b| b.database.as_ref())
            .map(|d| d.decoder())
            .ok_or("no database")?;
        let (message, codec) = decoder.message_at(index).ok_or("no such message")?;
        let texts: Vec<(&str, String)> = object
            .iter()
            .map(|(name, value)| {
                let text = match value {
                    Json::String(s) => Ok(s.clone()),
                    Json::Number(n) => Ok(n.to_string()),
                    other => Err(format!("signal {name}: {other} is not a number or a name")),
                }?;
                Ok((name.as_str(), text))
            })
            .collect::<Result<_, String>>()?;
        let named: Vec<Named<'_>> = texts
            .iter()
            .map(|(signal, text)| Named {
                signal,
                value: Given::from_text(text),
                shown: text,
            })
            .collect();
        let payload = encode_named(
            message,
            codec,
            &named,
            Encoding::frame(EncodeMode::Strict, counter),
        )
        .map_err(|e| e.to_string())?;
        let id = if message.extended {
            Id::extended(message.id)
        } else {
            Id::standard(message.id)
        }
        .map_err(|e| format!("message {}: {e}", message.name))?;
        let (fd, brs) = decoder.fd_format(message);
        if fd {
            FdFrame::padded(id, &payload, brs, false)
                .map(Frame::Fd)
                .map_err(|e| e.to_string())
        } else {
            Frame::classic(id, &payload).map_err(|e| e.to_string())
        }
    }

    /// Send `payload` (made only when someone subscribed) on channel `index` to its
    /// subscribers.
    fn publish(&self, index: usize, time: u64, payload: impl FnOnce() -> Vec<u8>) {
        if !self.subscribed(index) {
            return;
        }
        let payload = payload();
        let channel = next_id_of(index);
        for client in self.clients().iter_mut() {
            if let Some(subscription) = client.subscriptions.get(&channel) {
                let data = foxglove::message_data(*subscription, time, &payload);
                client.push(Outgoing::Binary(data));
            }
        }
    }

    /// The index [`HubBuilder::channel`]'s `n`th channel has, for [`Hub::publish_json`].
    pub fn extra_channel(&self, n: usize) -> usize {
        self.extra_base + n
    }

    /// Publish a JSON message of the caller's on channel `index`.
    pub fn publish_json(&self, index: usize, time: Timestamp, message: &Json) {
        self.publish(index, time.as_nanos(), || message.to_string().into_bytes());
    }

    /// One frame from bus `bus`: counted, and published raw and decoded.
    pub fn on_frame(&self, bus: usize, received: &Received, scratch: &mut Vec<Option<Decoded>>) {
        let Some(slot) = self.buses.get(bus) else {
            return;
        };
        let frame = &received.frame;
        let counters = &slot.counters;
        counters.frames.fetch_add(1, Ordering::Relaxed);
        if let Frame::Error(error) = frame {
            counters.errors.fetch_add(1, Ordering::Relaxed);
            if let Some(state) = state_told(error) {
                counters.state.store(state, Ordering::Relaxed);
            }
            if let Some((tec, rec)) = error.counters() {
                let packed = 1 << 16 | u32::from(tec) << 8 | u32::from(rec);
                counters.counters.store(packed, Ordering::Relaxed);
            }
        } else {
            counters.bits.fetch_add(
                u64::from(frame_bits(frame, Stuffing::Exact)),
                Ordering::Relaxed,
            );
        }
        let base = slot.base;
        let time = received.timestamp.as_nanos();
        let database = slot.database.as_deref();
        let decoded = database.and_then(|d| d.decoder.decode_into(frame, scratch));
        let name = decoded.as_ref().map(|(_, m, _)| m.display_name());
        let batching = self.subscribed(base + BATCH);
        // The frame as JSON once, for the raw channel and the batch alike.
        let entry = (batching || self.subscribed(base))
            .then(|| frame_json(&slot.name, received.timestamp, frame, name));
        if let Some(entry) = &entry {
            self.publish(base, time, || entry.to_string().into_bytes());
        }
        let mut signals = None;
        let mut pdus = Vec::new();
        if let (Some((index, message, result)), Some(database)) = (decoded, database) {
            if let Some(contained) = database.decoder.contained(index, frame.data()) {
                for pdu in contained.flatten() {
                    let Some((pdu_message, codec, pdu_index)) = pdu.message else {
                        continue;
                    };
                    scratch.clear();
                    scratch.resize(codec.signal_count(), None);
                    if codec.decode(pdu.pdu.data, scratch).is_ok() {
                        self.publish_decoded(database, base, pdu_index, pdu_message, scratch, time);
                        if let Some(object) = batching
                            .then(|| database.object(pdu_index, pdu_message, scratch))
                            .flatten()
                        {
                            pdus.push(
                                json!({"name": pdu_message.display_name(), "signals": object}),
                            );
                        }
                    }
                }
            } else if result.is_ok() {
                self.publish_decoded(database, base, index, message, scratch, time);
                signals = batching
                    .then(|| database.object(index, message, scratch))
                    .flatten();
            }
        }
        if let Some(mut entry) = entry.filter(|_| batching) {
            if let Json::Object(object) = &mut entry {
                if let Some(signals) = signals {
                    object.insert("signals".into(), Json::Object(signals));
                }
                if !pdus.is_empty() {
                    object.insert("pdus".into(), Json::Array(pdus));
                }
            }
            let mut batch = slot
                .batch
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner);
            if batch.len() < MAX_BATCH {
                batch.push(entry);
            } else {
                counters.unbatched.fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    /// Send each bus's batch of frames gathered since the last call (every 50 ms).
    pub fn flush(&self, now: Timestamp) {
        for slot in &self.buses {
            let frames = std::mem::take(
                &mut *slot
                    .batch
                    .lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner),
            );
            if !frames.is_empty() {
                self.publish(slot.base + BATCH, now.as_nanos(), || {
                    json!({ "frames": frames }).to_string().into_bytes()
                });
            }
        }
    }

    fn publish_decoded(
        &self,
        database: &Database,
        base: usize,
        index: usize,
        message: &bywire_dbc::Message,
        values: &[Option<Decoded>],
        time: u64,
    ) {
        let Some(json) = database.json.get(index) else {
            return;
        };
        self.publish(base + FIRST_MESSAGE + index, time, || {
            Json::Object(json.object(message, values))
                .to_string()
                .into_bytes()
        });
    }

    /// Read bus `bus` until `stop` is set or the bus closes, publishing every frame.
    pub fn read_bus(&self, bus: usize, mut rx: Box<dyn BusRx>, stop: &AtomicBool) {
        let mut scratch = Vec::new();
        // Bounded by `stop` and by the bus's life.
        while !stop.load(Ordering::Relaxed) {
            match rx.recv(Some(Duration::from_millis(100))) {
                Ok(Some(received)) => self.on_frame(bus, &received, &mut scratch),
                Ok(None) => {}
                Err(BusError::Closed) | Err(_) => {
                    if let Some(slot) = self.buses.get(bus) {
                        slot.counters.closed.store(true, Ordering::Relaxed);
                    }
                    return;
                }
            }
            if let Some(slot) = self.buses.get(bus) {
                slot.counters
                    .dropped
                    .store(rx.stats().rx_dropped, Ordering::Relaxed);
            }
        }
    }

    /// Once a second: each bus's statistics (frames and errors since the start, frames per
    /// second and load over the last `seconds`), and a warning to each client that lost
    /// messages since the last tick. `last` holds the previous counts between calls.
    pub fn tick(&self, now: Timestamp, seconds: f64, last: &mut Vec<(u64, u64)>) {
        last.resize(self.buses.len(), (0, 0));
        for (slot, previous) in self.buses.iter().zip(last.iter_mut()) {
            let c = &slot.counters;
            let (frames, bits) = (
                c.frames.load(Ordering::Relaxed),
                c.bits.load(Ordering::Relaxed),
            );
            let rate = per_second(frames.saturating_sub(previous.0), seconds);
            let load = slot.bitrate.map(|b| {
                100.0 * per_second(bits.saturating_sub(previous.1), seconds) / f64::from(b)
            });
            *previous = (frames, bits);
            let state = STATES
                .get(usize::from(c.state.load(Ordering::Relaxed)))
                .filter(|s| !s.is_empty());
            let packed = c.counters.load(Ordering::Relaxed);
            let (tec, rec) = if packed >> 16 == 0 {
                (None, None)
            } else {
                (Some(packed >> 8 & 0xFF), Some(packed & 0xFF))
            };
            let stats = json!({
                "timestamp": time_json(now),
                "state": state,
                "tec": tec,
                "rec": rec,
                "bus": slot.name,
                "frames": frames,
                "errors": c.errors.load(Ordering::Relaxed),
                "frames_per_s": rate,
                "load_percent": load,
                "bitrate": slot.bitrate,
                "dropped": c.dropped.load(Ordering::Relaxed),
                "unbatched": c.unbatched.load(Ordering::Relaxed),
                "closed": c.closed.load(Ordering::Relaxed),
            });
            self.publish(slot.base + 1, now.as_nanos(), || {
                stats.to_string().into_bytes()
            });
        }
        for client in self.clients().iter_mut() {
            let lost = client.dropped - client.told_dropped;
            if lost > 0 {
                client.told_dropped = client.dropped;
                let text = format!(
                    "{lost} messages dropped: this client reads slower than the buses send \
                     ({} in all)",
                    client.dropped
                );
                client.push(Outgoing::Text(foxglove::status(Level::Warning, &text)));
            }
        }
    }

    /// What every client lost, in all.
    pub fn dropped(&self) -> u64 {
        self.clients().iter().map(|c| c.dropped).sum()
    }
}

fn next_id_of(index: usize) -> u32 {
    u32::try_from(index + 1).unwrap_or(u32::MAX)
}

fn per_second(count: u64, seconds: f64) -> f64 {
    if seconds > 0.0 {
        // Counts are far below 2^53: exact as floats.
        #[allow(clippy::cast_precision_loss)]
        let count = count as f64;
        count / seconds
    } else {
        0.0
    }
}

/// A time as Foxglove's JSON messages carry one.
pub fn time_json(at: Timestamp) -> Json {
    let nanos = at.as_nanos();
    json!({"sec": nanos / 1_000_000_000, "nsec": nanos % 1_000_000_000})
}

/// A frame as the `/BUS/frames` channel carries it.
pub fn frame_json(bus: &str, at: Timestamp, frame: &Frame, name: Option<&str>) -> Json {
    let (id, extended) = frame.id().map_or((0, false), |id| {
        (id.as_raw(), matches!(id, Id::Extended(_)))
    });
    json!({
        "timestamp": time_json(at),
        "bus": bus,
        "id": id,
        "extended": extended,
        "remote": frame.is_remote(),
        "error": matches!(frame, Frame::Error(_)),
        "fd": matches!(frame, Frame::Fd(_)),
        "brs": matches!(frame, Frame::Fd(f) if f.brs()),
        "esi": matches!(frame, Frame::Fd(f) if f.esi()),
        "dlc": frame.dlc().as_raw(),
        "data": frame.data(),
        "name": name,
    })
}

/// A frame from what a client published on `/BUS/frames`: `id` (a number, or hex text),
/// `extended`, `remote`, `fd`, `brs`, `data` (bytes, or hex text).
fn frame_from_json(object: &Map<String, Json>) -> Result<Frame, String> {
    let flag = |key: &str| object.get(key).and_then(Json::as_bool).unwrap_or(false);
    let id = match object.get("id") {
        Some(Json::Number(n)) => n.as_u64().and_then(|n| u32::try_from(n).ok()),
        Some(Json::String(s)) => u32::from_str_radix(s.trim_start_matches("0x"), 16).ok(),
        _ => None,
    }
    .ok_or("a frame needs 'id' (a number, or hex text)")?;
    let extended = flag("extended") || id > 0x7FF;
    let id = if extended {
        Id::extended(id)
    } else {
        Id::standard(id)
    }
    .map_err(|e| e.to_string())?;
    let data: Vec<u8> = match object.get("data") {
        None => Vec::new(),
        Some(Json::Array(items)) => items
            .iter()
            .map(|b| b.as_u64().and_then(|b| u8::try_from(b).ok()))
            .collect::<Option<_>>()
            .ok_or("'data' holds a value that is not a byte")?,
        Some(Json::String(hex)) => {
            let hex: String = hex.chars().filter(|c| !c.is_whitespace()).collect();
            (0..hex.len() / 2)
                .map(|i| {
                    hex.get(2 * i..2 * i + 2)
                        .and_then(|b| u8::from_str_radix(b, 16).ok())
                })
                .collect::<Option<_>>()
                .filter(|_| hex.len().is_multiple_of(2))
                .ok_or("'data' is not hex bytes")?
        }
        Some(_) => return Err("'data' must be bytes or hex text".into()),
    };
    if flag("remote") {
        let dlc = bywire_core::frame::Dlc::new(u8::try_from(data.len()).unwrap_or(8).min(8))
            .ok_or("a remote frame's length")?;
        return Ok(Frame::remote(id, dlc));
    }
    if flag("fd") {
        return FdFrame::padded(id, &data, flag("brs"), false)
            .map(Frame::Fd)
            .map_err(|e| e.to_string());
    }
    Frame::classic(id, &data).map_err(|e| e.to_string())
}

fn frame_schema() -> Json {
    json!({
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "bywire.CanFrame",
        "type": "object",
        "properties": {
            "timestamp": {"type": "object", "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}}},
            "bus": {"type": "string"},
            "id": {"type": "integer"},
            "extended": {"type": "boolean"},
            "remote": {"type": "boolean"},
            "error": {"type": "boolean"},
            "fd": {"type": "boolean"},
            "brs": {"type": "boolean"},
            "esi": {"type": "boolean"},
            "dlc": {"type": "integer"},
            "data": {"type": "array", "items": {"type": "integer", "minimum": 0, "maximum": 255}},
            "name": {"type": ["string", "null"], "description": "the message's name in the database"},
        },
    })
}

fn batch_schema() -> Json {
    json!({
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "bywire.CanFrames",
        "type": "object",
        "properties": {
            "frames": {"type": "array", "items": {"type": "object", "description": "a bywire.CanFrame, with its decoded `signals` (and a container's `pdus`) when the database knows it"}},
        },
    })
}

fn stats_schema() -> Json {
    json!({
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "bywire.BusStats",
        "type": "object",
        "properties": {
            "timestamp": {"type": "object", "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}}},
            "bus": {"type": "string"},
            "frames": {"type": "integer", "description": "frames since the start"},
            "errors": {"type": "integer", "description": "error frames since the start"},
            "frames_per_s": {"type": "number"},
            "load_percent": {"type": ["number", "null"], "description": "of the bitrate, when known"},
            "bitrate": {"type": ["integer", "null"]},
            "dropped": {"type": "integer", "description": "frames the receiving queue dropped"},
            "unbatched": {"type": "integer", "description": "frames left out of full batches"},
            "closed": {"type": "boolean"},
            "state": {"type": ["string", "null"], "description": "the controller's state, as its error frames said it"},
            "tec": {"type": ["integer", "null"], "description": "transmit error counter"},
            "rec": {"type": ["integer", "null"], "description": "receive error counter"},
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn error_frames_tell_the_controllers_state_and_counters() {
        use bywire_core::frame::{ErrorClass, ErrorFrame};
        let hub = HubBuilder::new("t")
            .bus("can0", None, None, None)
            .build()
            .unwrap();
        let session = hub.connect(false).unwrap();
        hub.handle(
            session.id,
            ClientMessage::Subscribe(vec![foxglove::Subscription {
                id: 5,
                channel_id: 2,
            }]),
        );
        let stats = |frames: &[ErrorFrame]| -> Json {
            let mut scratch = Vec::new();
            for error in frames {
                let received = Received {
                    frame: Frame::Error(*error),
                    timestamp: Timestamp::from_nanos(1),
                    own: false,
                    local: false,
                    hardware: None,
                };
                hub.on_frame(0, &received, &mut scratch);
            }
            hub.tick(Timestamp::from_nanos(2), 1.0, &mut Vec::new());
            let last = session
                .queue
                .try_iter()
                .filter_map(|m| match m {
                    Outgoing::Binary(data) => Some(data),
                    Outgoing::Text(_) => None,
                })
                .last()
                .unwrap();
            serde_json::from_slice(&last[13..]).unwrap()
        };
        let class = |classes: &[ErrorClass]| classes.iter().map(|c| c.bit()).sum::<u32>();
        let passive = ErrorFrame::from_array(
            class(&[ErrorClass::Controller, ErrorClass::Counters]),
            [0, 0x20, 0, 0, 0, 0, 130, 5],
        );
        let said = stats(&[passive]);
        assert_eq!(
            (&said["state"], &said["tec"], &said["rec"], &said["errors"]),
            (&json!("error-passive"), &json!(130), &json!(5), &json!(1))
        );
        let off = ErrorFrame::from_array(class(&[ErrorClass::BusOff]), [0; 8]);
        assert_eq!(stats(&[off])["state"], "bus-off");
        let back = ErrorFrame::from_array(class(&[ErrorClass::Restarted]), [0; 8]);
        assert_eq!(stats(&[back])["state"], "error-active");
    }

    #[test]
    fn published_frames_read_as_written() {
        let object = |text: &str| -> Map<String, Json> { serde_json::from_str(text).unwrap() };
        let frame = |text: &str| frame_from_json(&object(text)).map(|f| f.to_string());
        assert_eq!(
            frame(r#"{"id": 291, "data": [1, 2]}"#),
            Ok("123#0102".into())
        );
        assert_eq!(
            frame(r#"{"id": "1ABCDEF0", "data": "DE AD"}"#),
            Ok("1ABCDEF0#DEAD".into())
        );
        assert_eq!(
            frame(r#"{"id": 5, "extended": true}"#),
            Ok("00000005#".into())
        );
        assert_eq!(
            frame(r#"{"id": 5, "remote": true, "data": [0,0]}"#),
            Ok("005#R2".into())
        );
        assert!(frame(r#"{"data": [1]}"#).is_err());
        assert!(frame(r#"{"id": 1, "data": [256]}"#).is_err());
        assert!(frame(r#"{"id": 1, "data": "ABC"}"#).is_err());
        assert!(frame(r#"{"id": 1, "data": [1,2,3,4,5,6,7,8,9]}"#).is_err());
        assert!(frame(r#"{"id": 536870912}"#).is_err());
    }
}
