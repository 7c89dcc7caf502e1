// Foxglove's own WebSocket client (@foxglove/ws-protocol, over the `ws` package) against
// `bywire web`: it lists the channels, subscribes to a bus's raw frames and to one decoded
// message, prints "ready", collects what arrives until it has RAW frames and DECODED
// messages (frames with identifier 0x7FE are the test's readiness probes), then publishes a
// raw frame and a message by its signals, waits for their answers, and prints one JSON object
// with everything.
//
// usage: node foxglove_client.js URL BUS MESSAGE RAW DECODED
"use strict";

const { FoxgloveClient } = require("@foxglove/ws-protocol");
const WebSocket = require("ws");

const [url, bus, messageName, rawWanted, decodedWanted] = process.argv.slice(2);
const client = new FoxgloveClient({
  ws: new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]),
});
const result = { serverInfo: null, topics: [], raw: [], decoded: [], statuses: [] };
const bySubscription = new Map();
const text = new TextDecoder();
let done = false;

setTimeout(() => {
  console.error("timed out: " + JSON.stringify(result).slice(0, 2000));
  process.exit(2);
}, 30000);

client.on("serverInfo", (info) => { result.serverInfo = info; });
client.on("status", (status) => { result.statuses.push(status); });
client.on("error", (error) => { console.error(String(error)); process.exit(3); });
client.on("advertise", (channels) => {
  for (const channel of channels) {
    result.topics.push({ topic: channel.topic, schemaName: channel.schemaName, encoding: channel.encoding, schema: channel.schema });
    if (channel.topic === `/${bus}/frames` || channel.topic === `/${bus}/${messageName}`) {
      bySubscription.set(client.subscribe(channel.id), channel.topic);
    }
  }
  // Subscriptions go out in order before anything this client is sent afterwards.
  setTimeout(() => console.log("ready"), 200);
});
client.on("message", ({ subscriptionId, timestamp, data }) => {
  const topic = bySubscription.get(subscriptionId);
  const object = JSON.parse(text.decode(data));
  const entry = { topic, timestamp: timestamp.toString(), message: object };
  if (topic.endsWith("/frames")) {
    if (object.id === 0x7fe) return;
    result.raw.push(entry);
  } else {
    result.decoded.push(entry);
  }
  if (!done && result.raw.length >= Number(rawWanted) && result.decoded.length >= Number(decodedWanted)) {
    done = true;
    publishAndFinish();
  }
});

function publishAndFinish() {
  const encoder = new TextEncoder();
  const frames = client.advertise({ topic: `/${bus}/frames`, encoding: "json", schemaName: "bywire.CanFrame" });
  const control = client.advertise({ topic: `/${bus}/AdsToVehicle_Control`, encoding: "json", schemaName: "AdsToVehicle_Control" });
  client.sendMessage(frames, encoder.encode(JSON.stringify({ id: 0x123, data: [0xde, 0xad, 0xbe, 0xef] })));
  client.sendMessage(control, encoder.encode(JSON.stringify({ VelocityCmd: 2.5, GearCmd: "Reverse" })));
  // A message that cannot be encoded: answered with an error status, nothing sent.
  client.sendMessage(control, encoder.encode(JSON.stringify({ VelocityCmd: 99 })));
  // Done when the answers are in: with sending allowed, the two frames back from the bus and
  // the refusal of the third; without, the refusals of both channels (the timeout above
  // bounds the wait).
  const sends = (result.serverInfo.capabilities || []).includes("clientPublish");
  const answered = () => sends
    ? result.raw.length >= Number(rawWanted) + 2 && result.statuses.some((s) => s.message.includes("VelocityCmd"))
    : result.statuses.length >= 2;
  const check = setInterval(() => {
    if (!answered()) return;
    clearInterval(check);
    console.log(JSON.stringify(result));
    client.close();
    process.exit(0);
  }, 20);
}
