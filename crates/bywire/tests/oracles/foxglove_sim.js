// Foxglove's own client against `bywire sim --web`: it subscribes to the tug's pose, route
// and state, presses the page's E-stop (a message on /tug/command) once it has seen a few
// poses, and waits for the tug to say it is stopping. Prints one JSON object with what it
// received and Foxglove's own JSON Schemas (@foxglove/schemas) for the test to validate with.
//
// usage: node foxglove_sim.js URL
"use strict";

const { FoxgloveClient } = require("@foxglove/ws-protocol");
const schemas = require("@foxglove/schemas/jsonschema");
const WebSocket = require("ws");

const client = new FoxgloveClient({
  ws: new WebSocket(process.argv[2], [FoxgloveClient.SUPPORTED_SUBPROTOCOL]),
});
const result = {
  channels: {}, poses: [], route: null, states: [], statuses: [],
  schemas: { PoseInFrame: schemas.PoseInFrame, PosesInFrame: schemas.PosesInFrame },
};
const topics = new Map();
const text = new TextDecoder();
let pressed = false;

setTimeout(() => {
  console.error("timed out: " + JSON.stringify(result).slice(0, 3000));
  process.exit(2);
}, 60000);

client.on("status", (status) => result.statuses.push(status));
client.on("advertise", (channels) => {
  for (const channel of channels) {
    if (channel.topic.startsWith("/tug/")) {
      result.channels[channel.topic] = channel.schemaName;
      topics.set(client.subscribe(channel.id), channel.topic);
    }
  }
});
client.on("message", ({ subscriptionId, data }) => {
  const topic = topics.get(subscriptionId);
  const message = JSON.parse(text.decode(data));
  if (topic === "/tug/pose") result.poses.push(message);
  else if (topic === "/tug/route") result.route = message;
  else if (topic === "/tug/state") {
    result.states.push(message);
    if (pressed && message.estop !== "Normal") {
      console.log(JSON.stringify(result));
      client.close();
      process.exit(0);
    }
  }
  if (!pressed && result.poses.length >= 5 && result.route) {
    pressed = true;
    const command = client.advertise({ topic: "/tug/command", encoding: "json", schemaName: "" });
    client.sendMessage(command, new TextEncoder().encode(JSON.stringify({ estop: true })));
  }
});
