// bywire's page: a Foxglove WebSocket client (the protocol the server speaks to Foxglove too)
// with a trace, a signal tree, plots (uPlot) and a transmit panel. Data arrive at bus speed;
// the page draws at most ten times a second, so a busy bus costs the page a bounded effort.
"use strict";

const token = new URLSearchParams(location.search).get("token");
const withToken = (path) => (token ? `${path}?token=${encodeURIComponent(token)}` : path);
const $ = (id) => document.getElementById(id);
const hex = (n, width) => n.toString(16).toUpperCase().padStart(width, "0");

const state = {
  channels: new Map(),      // channel id -> channel
  capabilities: [],
  database: { buses: [] },   // each bus with its database's messages
  rows: new Map(),          // fixed mode: "bus/id" -> row
  byName: new Map(),        // "bus/message" -> its row
  scroll: [],               // scrolling mode: the latest frames
  decodedLatest: new Map(), // "bus/name" -> decoded object
  stats: new Map(),         // bus -> statistics
  paused: false,
  fixed: true,
  filter: [],
  panels: [],
  current: null,
  received: 0,
  start: null,              // the first frame's time: the trace counts from it
  latest: 0,                // the newest frame's time
  dirty: true,
};
const SCROLL_ROWS = 500;
// Rows the trace draws at most (a bus of 2,000 identifiers would otherwise cost the page more
// than its frames do); a filter narrows what they are.
const TRACE_ROWS = 200;
const PLOT_POINTS = 20000;

// ---- the protocol --------------------------------------------------------------------------
let socket = null;
const clientChannels = new Map(); // topic -> client channel id

function connect() {
  const url = `${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/${token ? `?token=${encodeURIComponent(token)}` : ""}`;
  socket = new WebSocket(url, ["foxglove.websocket.v1"]);
  socket.binaryType = "arraybuffer";
  socket.onopen = () => say("connected");
  socket.onclose = () => { say("disconnected: reload the page to connect again", true); $("server").textContent = "disconnected"; };
  socket.onmessage = (event) => (typeof event.data === "string" ? onText(JSON.parse(event.data)) : onBinary(event.data));
}

function onText(message) {
  switch (message.op) {
    case "serverInfo":
      state.capabilities = message.capabilities || [];
      $("server").textContent = message.name;
      $("send-pane").hidden = !state.capabilities.includes("clientPublish");
      break;
    case "advertise": {
      if (message.channels.some((c) => c.topic === "/tug/state")) $("tug-pane").hidden = false;
      // Each bus's batches (every frame with its signals, 20 messages a second however busy
      // the bus) and statistics, and the channels that are not a bus's: not a message per frame.
      const wanted = ["bywire.CanFrames", "bywire.BusStats", "bywire.TugState", "foxglove.PosesInFrame"];
      const subscriptions = [];
      for (const channel of message.channels) {
        state.channels.set(channel.id, channel);
        if (wanted.includes(channel.schemaName)) subscriptions.push({ id: channel.id, channelId: channel.id });
      }
      socket.send(JSON.stringify({ op: "subscribe", subscriptions }));
      break;
    }
    case "status":
      say(message.message, message.level >= 2);
      break;
  }
}

const decoder = new TextDecoder();
function onBinary(buffer) {
  const view = new DataView(buffer);
  if (view.getUint8(0) !== 1) return;
  const channel = state.channels.get(view.getUint32(1, true));
  if (!channel) return;
  const time = Number(view.getBigUint64(5, true)) / 1e9;
  const message = JSON.parse(decoder.decode(new Uint8Array(buffer, 13)));
  const topic = channel.topic;
  const slash = topic.lastIndexOf("/");
  const bus = topic.slice(1, slash);
  const leaf = topic.slice(slash + 1);
  if (channel.schemaName === "foxglove.PosesInFrame" && topic === "/tug/route") state.route = message.poses;
  else if (channel.schemaName === "bywire.TugState") { state.tug = message; state.tugDirty = true; }
  else if (channel.schemaName === "bywire.CanFrames") {
    for (const f of message.frames) {
      const at = f.timestamp.sec + f.timestamp.nsec / 1e9;
      onFrame(at, f);
      if (f.signals) onDecoded(at, f.bus, f.name, f.signals);
      for (const pdu of f.pdus || []) onDecoded(at, f.bus, pdu.name, pdu.signals);
    }
  } else if (leaf === "stats" && channel.schemaName === "bywire.BusStats") state.stats.set(bus, message);
}

function publish(topic, object) {
  let id = clientChannels.get(topic);
  if (id === undefined) {
    id = clientChannels.size + 1;
    clientChannels.set(topic, id);
    socket.send(JSON.stringify({ op: "advertise", channels: [{ id, topic, encoding: "json", schemaName: "" }] }));
  }
  const body = new TextEncoder().encode(JSON.stringify(object));
  const data = new Uint8Array(5 + body.length);
  data[0] = 1;
  new DataView(data.buffer).setUint32(1, id, true);
  data.set(body, 5);
  socket.send(data);
}

// ---- frames, decoded values, statistics ----------------------------------------------------
function onFrame(time, f) {
  state.received++;
  if (state.start === null) state.start = time;
  if (time > state.latest) state.latest = time;
  if (state.paused) return;
  // One row per identifier, updated in place (a busy bus allocates nothing per frame here).
  const key = `${f.bus}/${f.id}/${f.extended}`;
  let row = state.rows.get(key);
  if (!row) {
    row = { bus: f.bus, id: f.id, extended: f.extended, name: f.name, count: 0, period: null, time, data: [], changedAt: [], decoded: null };
    state.rows.set(key, row);
    if (f.name) state.byName.set(`${f.bus}/${f.name}`, row);
  } else {
    row.period = (time - row.time) * 1e3;
  }
  const first = row.count === 0;
  for (let i = 0; i < f.data.length; i++) {
    if (first) row.changedAt[i] = -1e9;
    else if (row.data[i] !== f.data[i]) row.changedAt[i] = time;
  }
  row.count++;
  row.time = time;
  row.data = f.data;
  row.error = f.error;
  row.remote = f.remote;
  row.fd = f.fd;
  // The scrolling trace keeps the frames themselves.
  f.time = time;
  f.decoded = null;
  state.scroll.push(f);
  if (state.scroll.length > SCROLL_ROWS * 2) state.scroll.splice(0, state.scroll.length - SCROLL_ROWS);
  state.dirty = true;
}

function onDecoded(time, bus, name, values) {
  state.decodedLatest.set(`${bus}/${name}`, values);
  if (!state.paused) {
    // The frame it came from arrived just before it, on the raw channel.
    const row = state.byName.get(`${bus}/${name}`);
    if (row) row.decoded = values;
    const last = state.scroll[state.scroll.length - 1];
    if (last && last.bus === bus && last.name === name) last.decoded = values;
  }
  for (const panel of state.panels) {
    for (const series of panel.series) {
      if (series.log === null && series.bus === bus && series.message === name && series.signal in values) {
        const v = values[series.signal];
        series.x.push(time);
        series.y.push(typeof v === "number" ? v : null);
        if (series.x.length > PLOT_POINTS) { series.x.splice(0, PLOT_POINTS / 10); series.y.splice(0, PLOT_POINTS / 10); }
        panel.dirty = true;
      }
    }
  }
}

// ---- filters: an identifier (hex), a name, or SIGNAL=|<|>VALUE; all must match -------------
function parseFilter(text) {
  return text.trim().split(/\s+/).filter(Boolean).map((term) => {
    const m = term.match(/^([A-Za-z_][\w#]*)(<=|>=|=|<|>)(.+)$/);
    if (m) return { signal: m[1], op: m[2], value: m[3] };
    const id = term.replace(/^0x/i, "");
    return { text: term.toLowerCase(), id: /^[0-9a-f]+$/i.test(id) ? parseInt(id, 16) : null };
  });
}

function matches(row) {
  return state.filter.every((t) => {
    if (t.signal) {
      if (!row.decoded || !(t.signal in row.decoded)) return false;
      const v = row.decoded[t.signal];
      const n = Number(t.value);
      const choice = row.decoded[`${t.signal}_choice`];
      switch (t.op) {
        case "=": return Number.isNaN(n) ? choice === t.value : v === n;
        case "<": return v < n;
        case ">": return v > n;
        case "<=": return v <= n;
        case ">=": return v >= n;
      }
      return false;
    }
    return row.id === t.id || (row.name || "").toLowerCase().includes(t.text);
  });
}

// ---- drawing -------------------------------------------------------------------------------
function signalsText(decoded) {
  if (!decoded) return "";
  return Object.entries(decoded)
    .filter(([k]) => !k.endsWith("_choice"))
    .map(([k, v]) => {
      const choice = decoded[`${k}_choice`];
      return `${k}: ${choice != null ? choice : v}`;
    })
    .join(", ");
}

function rowHtml(row, now) {
  const data = row.remote ? "remote" : row.data.map((b, i) =>
    (state.fixed && now - row.changedAt[i] < 1 ? `<span class="changed">${hex(b, 2)}</span>` : hex(b, 2))).join(" ");
  const shownTime = row.time;
  const id = row.error ? "ERROR" : hex(row.id, row.extended ? 8 : 3);
  const cells = [
    (shownTime - state.start).toFixed(6), row.bus, id, row.name || "", row.data.length, data,
    state.fixed ? row.count : "", state.fixed && row.period != null ? row.period.toFixed(1) : "",
  ];
  const escape = (s) => String(s).replace(/[&<>]/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;" })[c]);
  return `<tr${row.error ? ' class="error-row"' : ""} data-id="${id}" title="${new Date(row.time * 1e3).toISOString()}">${cells.map((c, i) => `<td>${i === 5 ? c : escape(c)}</td>`).join("")}<td class="signals">${escape(signalsText(row.decoded))}</td></tr>`;
}

function drawTrace() {
  const now = state.latest;
  let rows = state.fixed
    ? [...state.rows.values()].sort((a, b) => a.bus.localeCompare(b.bus) || a.id - b.id)
    : state.scroll.slice(-SCROLL_ROWS);
  rows = rows.filter(matches);
  const more = rows.length - TRACE_ROWS;
  if (more > 0) rows = state.fixed ? rows.slice(0, TRACE_ROWS) : rows.slice(-TRACE_ROWS);
  const html = rows.map((r) => rowHtml(r, now));
  if (more > 0) html.push(`<tr><td colspan="9" class="hint">${more} more rows: a filter narrows them</td></tr>`);
  document.querySelector("#trace tbody").innerHTML = html.join("");
}

function drawBuses() {
  $("buses").innerHTML = [...state.stats.values()].map((s) => {
    const load = s.load_percent != null ? ` · ${s.load_percent.toFixed(1)} %` : "";
    const errors = s.errors ? ` · ${s.errors} errors` : "";
    const dropped = s.dropped ? ` · ${s.dropped} dropped` : "";
    const controller = s.state ? ` · ${s.state}${s.tec != null ? ` (TEC ${s.tec}, REC ${s.rec})` : ""}` : "";
    return `<span class="bus-chip${s.closed || s.state === "bus-off" || s.state === "error-passive" ? " closed" : ""}" data-bus="${s.bus}">${s.bus}: ${Math.round(s.frames_per_s)} frames/s${load}${errors}${dropped}${controller}</span>`;
  }).join(" ");
}

// ---- plots ---------------------------------------------------------------------------------
const COLOURS = ["#4fb3ff", "#ffb347", "#7ee787", "#ff6b6b", "#d2a8ff", "#f2cc60"];

function addPanel() {
  const element = document.createElement("div");
  element.className = "panel";
  element.innerHTML = `<div class="bar"><span class="title">(click a signal)</span><span class="spacer"></span><button class="close">×</button></div><div class="chart"></div>`;
  $("plots").appendChild(element);
  const panel = { element, series: [], plot: null, dirty: false, following: true };
  element.addEventListener("click", () => selectPanel(panel));
  element.querySelector(".close").addEventListener("click", (e) => {
    e.stopPropagation();
    if (panel.plot) panel.plot.destroy();
    element.remove();
    state.panels = state.panels.filter((p) => p !== panel);
    if (state.current === panel) state.current = state.panels[0] || null;
  });
  state.panels.push(panel);
  selectPanel(panel);
  return panel;
}

function selectPanel(panel) {
  state.current = panel;
  for (const p of state.panels) p.element.classList.toggle("current", p === panel);
}

function plotSignal(bus, message, signal, unit) {
  const panel = state.current || addPanel();
  if (panel.series.some((s) => s.bus === bus && s.message === message && s.signal === signal)) return;
  const series = { bus, message, signal, unit, x: [], y: [], log: null };
  panel.series.push(series);
  if (player.log !== null && player.summary) {
    // A log's bus: the first of its buses the database's message is on (a log names its own).
    series.log = player.log;
    series.bus = Object.keys(player.summary.buses).includes(bus) ? bus : Object.keys(player.summary.buses)[0];
    plotFromLog(panel, series, player.summary.start, player.summary.end);
  }
  panel.element.querySelector(".title").textContent = panel.series.map((s) => `${s.message}.${s.signal}`).join(", ");
  if (panel.plot) { panel.plot.destroy(); panel.plot = null; }
  panel.dirty = true;
}

function drawPlot(panel) {
  if (!panel.series.length) return;
  const tables = panel.series.map((s) => [s.x, s.y]);
  const data = tables.length === 1 ? [tables[0][0].slice(), tables[0][1].slice()] : uPlot.join(tables);
  if (!panel.plot) {
    const chart = panel.element.querySelector(".chart");
    panel.plot = new uPlot({
      width: Math.max(300, chart.clientWidth || 600), height: 220,
      scales: { x: { time: true } },
      axes: [{ stroke: "#8a93a0", grid: { stroke: "#2c323c" } }, { stroke: "#8a93a0", grid: { stroke: "#2c323c" } }],
      series: [{}, ...panel.series.map((s, i) => ({
        label: `${s.message}.${s.signal}${s.unit ? ` [${s.unit}]` : ""}`, stroke: COLOURS[i % COLOURS.length], spanGaps: true, width: 1.5,
      }))],
      hooks: { setSelect: [(u) => {
        panel.following = false;
        // A log's series: the span chosen, read again at full detail.
        const from = u.posToVal(u.select.left, "x"), to = u.posToVal(u.select.left + u.select.width, "x");
        for (const s of panel.series) if (s.log !== null && u.select.width > 0) plotFromLog(panel, s, from, to);
      }] },
      cursor: { drag: { x: true, y: false } },
    }, data, chart);
    panel.plot.over.addEventListener("dblclick", () => { panel.following = true; panel.dirty = true; });
    // The wheel zooms about the cursor; with shift it pans.
    panel.plot.over.addEventListener("wheel", (e) => {
      e.preventDefault();
      const u = panel.plot;
      const { min, max } = u.scales.x;
      if (min == null || max == null) return;
      const width = max - min;
      let [from, to] = [min, max];
      if (e.shiftKey) {
        const shift = (width * Math.sign(e.deltaY)) / 10;
        [from, to] = [min + shift, max + shift];
      } else {
        const at = u.posToVal(e.offsetX, "x");
        const factor = e.deltaY > 0 ? 1.25 : 0.8;
        [from, to] = [at - (at - min) * factor, at + (max - at) * factor];
      }
      panel.following = false;
      u.setScale("x", { min: from, max: to });
      clearTimeout(panel.refetch);
      panel.refetch = setTimeout(() => {
        for (const s of panel.series) if (s.log !== null) plotFromLog(panel, s, from, to);
      }, 200);
    }, { passive: false });
  } else if (panel.following) {
    panel.plot.setData(data);
  } else {
    panel.plot.setData(data, false);
  }
}

// ---- the tree and the transmit panel -------------------------------------------------------
function busDatabase(name) {
  return state.database.buses.find((b) => b.name === name) || { name, messages: [] };
}

function buildTree() {
  const tree = $("tree");
  const buses = state.database.buses;
  // The logs' database has a group of its own only without live buses: with them, a signal
  // clicked while a log is chosen is plotted from the log.
  const groups = state.database.logs && !buses.length ? [{ name: "logs", messages: state.database.logs.messages }] : buses;
  tree.innerHTML = "";
  for (const bus of groups) {
    let parent = tree;
    if (groups.length > 1) {
      const group = document.createElement("details");
      group.open = true;
      group.innerHTML = `<summary>${bus.name}</summary>`;
      tree.appendChild(group);
      parent = group;
    }
    for (const message of bus.messages) {
      const details = document.createElement("details");
      details.innerHTML = `<summary title="${message.name}">${message.name} <span class="unit">${hex(message.id, message.extended ? 8 : 3)}</span></summary>`;
      for (const signal of message.signals) {
        const item = document.createElement("div");
        item.className = "signal";
        item.dataset.signal = `${bus.name}/${message.name}/${signal.name}`;
        item.innerHTML = `${signal.name} <span class="unit">${signal.unit || ""}</span>`;
        item.addEventListener("click", () => plotSignal(bus.name, message.name, signal.name, signal.unit));
        details.appendChild(item);
      }
      parent.appendChild(details);
    }
  }
  const busSelect = $("send-bus");
  busSelect.innerHTML = buses.map((b) => `<option>${b.name}</option>`).join("");
  busSelect.addEventListener("change", showSendMessages);
  $("send-message").addEventListener("change", showSendFields);
  showSendMessages();
}

function showSendMessages() {
  const select = $("send-message");
  select.innerHTML = '<option value="">raw frame</option>';
  for (const message of busDatabase($("send-bus").value).messages) {
    const option = document.createElement("option");
    option.value = option.textContent = message.name;
    select.appendChild(option);
  }
  showSendFields();
}

function showSendFields() {
  const name = $("send-message").value;
  $("send-raw").hidden = name !== "";
  const message = busDatabase($("send-bus").value).messages.find((m) => m.name === name);
  $("send-signals").innerHTML = message ? message.signals.map((s) => {
    const options = s.choices.length ? ` list="choices-${s.name}"` : "";
    const list = s.choices.length ? `<datalist id="choices-${s.name}">${s.choices.map(([, l]) => `<option value="${l}">`).join("")}</datalist>` : "";
    return `<label>${s.name} <span class="unit">${s.unit || ""}</span> <input data-signal="${s.name}" placeholder="start value"${options} size="10">${list}</label>`;
  }).join("") : "";
}

function sendOnce() {
  const bus = $("send-bus").value;
  const name = $("send-message").value;
  if (name === "") {
    const data = $("send-data").value.replace(/\s+/g, "");
    publish(`/${bus}/frames`, { id: $("send-id").value.trim(), data, extended: $("send-ext").checked, fd: $("send-fd").checked });
  } else {
    const values = {};
    for (const input of document.querySelectorAll("#send-signals input")) {
      if (input.value.trim() !== "") values[input.dataset.signal] = Number.isNaN(Number(input.value)) ? input.value : Number(input.value);
    }
    publish(`/${bus}/${name}`, values);
  }
  $("send-said").textContent = `sent at ${new Date().toLocaleTimeString()}`;
}

let periodic = null;
function startPeriodic() {
  const period = Math.max(1, Number($("send-period").value) || 100);
  stopPeriodic();
  periodic = setInterval(sendOnce, period);
  $("send-start").disabled = true;
  $("send-stop").disabled = false;
}
function stopPeriodic() {
  if (periodic) clearInterval(periodic);
  periodic = null;
  $("send-start").disabled = false;
  $("send-stop").disabled = true;
}

// ---- the simulated tug: its route, where it is, its state, the fault buttons --------------
function drawTug() {
  const tug = state.tug;
  if (!tug || !state.tugDirty) return;
  state.tugDirty = false;
  const canvas = $("map");
  const g = canvas.getContext("2d");
  g.clearRect(0, 0, canvas.width, canvas.height);
  const points = (state.route || []).map((p) => p.position).concat([{ x: tug.x, y: tug.y }]);
  const xs = points.map((p) => p.x), ys = points.map((p) => p.y);
  const [x0, x1, y0, y1] = [Math.min(...xs) - 5, Math.max(...xs) + 5, Math.min(...ys) - 5, Math.max(...ys) + 5];
  const scale = Math.min(canvas.width / (x1 - x0), canvas.height / (y1 - y0));
  const at = (p) => [(p.x - x0) * scale, canvas.height - (p.y - y0) * scale];
  g.strokeStyle = "#4a5260";
  g.lineWidth = 2;
  g.beginPath();
  (state.route || []).forEach((p, i) => { const [x, y] = at(p.position); i ? g.lineTo(x, y) : g.moveTo(x, y); });
  g.stroke();
  const [x, y] = at(tug);
  const yaw = (tug.yaw_deg * Math.PI) / 180;
  g.save();
  g.translate(x, y);
  g.rotate(-yaw);
  g.fillStyle = "#ffb347";
  g.beginPath();
  g.moveTo(9, 0); g.lineTo(-6, 5); g.lineTo(-6, -5); g.closePath();
  g.fill();
  g.restore();
  const rows = [
    ["phase", tug.phase || "-"], ["speed", `${tug.speed_mps.toFixed(2)} m/s`],
    ["wheels", tug.wheels_deg.map((w) => `${w.toFixed(1)}°`).join(" ")],
    ["mode", tug.mode || "-"], ["watchdog", tug.watchdog || "-"], ["E-stop", tug.estop || "-"],
    ["level", tug.level || "-"], ["redundancy", tug.redundancy || "-"],
    ["faults", tug.faults.length ? tug.faults.join(", ") : "none"], ["battery", `${tug.soc_percent.toFixed(1)} %`],
  ];
  $("tug-state").innerHTML = rows.map(([k, v]) => `<tr><td>${k}</td><td${k === "level" && v !== "nominal" && v !== "-" ? ' class="level-bad"' : ""}>${v}</td></tr>`).join("");
  const buttons = $("tug-buttons");
  if (buttons.querySelectorAll(".fault").length !== tug.buttons.length) {
    buttons.querySelectorAll(".fault").forEach((b) => b.remove());
    for (const b of tug.buttons) {
      const button = document.createElement("button");
      button.className = "fault";
      button.dataset.fault = b.number;
      button.textContent = `${b.number} ${b.fault}`;
      buttons.appendChild(button);
    }
  }
}

$("tug-buttons").addEventListener("click", (e) => {
  const b = e.target.closest("button");
  if (!b) return;
  if (b.dataset.fault) publish("/tug/command", { fault: Number(b.dataset.fault) });
  else publish("/tug/command", { [b.dataset.command]: true });
});

function say(text, error) {
  const status = $("status");
  status.textContent = text;
  status.classList.toggle("error", !!error);
}

// ---- logs: a player fed by the server's frames, plots of a whole log, export ---------------
const api = (path, params) => {
  const query = new URLSearchParams(params);
  if (token) query.set("token", token);
  return fetch(`${path}?${query}`, { headers: { "X-Bywire": "1" } }).then((r) => {
    if (!r.ok) return r.text().then((t) => { throw new Error(t.trim()); });
    return r;
  });
};
const player = { log: null, summary: null, at: 0, playing: false, buffer: [], next: null, fetching: false };

function feed(f) {
  const time = f.timestamp.sec + f.timestamp.nsec / 1e9;
  onFrame(time, f);
  if (f.signals) onDecoded(time, f.bus, f.name, f.signals);
  player.at = time;
  $("log-at").value = (time - player.summary.start).toFixed(3);
}

// The frames after `player.next` into the buffer (the server reads on from where it stopped).
function refill() {
  if (player.fetching || player.next === null) return Promise.resolve();
  player.fetching = true;
  const from = typeof player.next === "string" ? { from_ns: player.next } : { from: player.next };
  return api("/api/logs/frames", { log: player.log, ...from, count: 2000 })
    .then((r) => r.json())
    .then((answer) => { player.buffer.push(...answer.frames); player.next = answer.next_ns; })
    .catch((e) => say(e.message, true))
    .finally(() => { player.fetching = false; });
}

function jump(at) {
  player.buffer = [];
  player.next = at;
  player.at = at;
  return refill();
}

let lastTick = performance.now();
setInterval(() => {
  const now = performance.now();
  const elapsed = (now - lastTick) / 1000;
  lastTick = now;
  if (!player.playing || player.log === null) return;
  const until = player.at + elapsed * Number($("log-speed").value);
  // Bounded by the buffer.
  while (player.buffer.length) {
    const f = player.buffer[0];
    if (f.timestamp.sec + f.timestamp.nsec / 1e9 > until) break;
    feed(player.buffer.shift());
  }
  player.at = Math.max(player.at, until);
  if (player.buffer.length < 500) refill();
  if (!player.buffer.length && player.next === null) { player.playing = false; $("log-play").textContent = "play"; say("the end of the log"); }
}, 50);

function chooseLog(value) {
  player.playing = false;
  $("log-play").textContent = "play";
  if (value === "") { player.log = null; $("log-summary").textContent = ""; return; }
  player.log = Number(value);
  $("log-summary").textContent = "reading…";
  api("/api/logs/summary", { log: player.log }).then((r) => r.json()).then((summary) => {
    player.summary = summary;
    const buses = Object.entries(summary.buses).map(([b, n]) => `${b} (${n})`).join(", ");
    $("log-summary").textContent = `${summary.format}, ${summary.frames} frames, ${(summary.end - summary.start).toFixed(1)} s; ${buses}`;
    player.buffer = [];
    player.next = summary.start_ns;
    player.at = summary.start;
    refill();
  }).catch((e) => say(e.message, true));
}

/// A signal over the whole log (or the span shown), decimated by the server.
function plotFromLog(panel, series, from, to) {
  const width = panel.element.querySelector(".chart").clientWidth || 800;
  return api("/api/logs/series", {
    log: series.log, bus: series.bus, message: series.message, signal: series.signal,
    from, to, points: Math.max(200, Math.round(width * 2)),
  }).then((r) => r.json()).then((answer) => {
    series.x = answer.x;
    series.y = answer.y;
    series.samples = answer.samples;
    panel.dirty = true;
  }).catch((e) => say(e.message, true));
}

function addLogOption(id, name) {
  const option = document.createElement("option");
  option.value = id;
  option.textContent = name;
  $("log-select").appendChild(option);
}

function setupLogs() {
  return api("/api/logs", {}).then((r) => r.json()).then((answer) => {
    if (!answer.logs.length && !answer.upload) return;
    $("logs-pane").hidden = false;
    $("log-upload-label").hidden = !answer.upload;
    for (const log of answer.logs) addLogOption(log.id, log.name);
  });
}

// Uploaded logs: sent as they are; the server reads their format from their content.
$("log-upload").addEventListener("change", (e) => {
  for (const file of e.target.files) {
    say(`uploading ${file.name}…`);
    const query = new URLSearchParams({ name: file.name });
    if (token) query.set("token", token);
    fetch(`/api/logs/upload?${query}`, { method: "POST", body: file, headers: { "X-Bywire": "1" } })
      .then((r) => (r.ok ? r.json() : r.text().then((t) => { throw new Error(t.trim()); })))
      .then((answer) => {
        addLogOption(answer.id, file.name);
        $("log-select").value = String(answer.id);
        chooseLog(String(answer.id));
        say(`${file.name} uploaded`);
      })
      .catch((error) => say(`${file.name}: ${error.message}`, true));
  }
});

$("log-select").addEventListener("change", (e) => chooseLog(e.target.value));
$("log-play").addEventListener("click", () => {
  if (player.log === null) return;
  player.playing = !player.playing;
  $("log-play").textContent = player.playing ? "pause" : "play";
});
$("log-step").addEventListener("click", () => {
  if (player.log === null) return;
  player.playing = false;
  $("log-play").textContent = "play";
  (player.buffer.length ? Promise.resolve() : refill()).then(() => { if (player.buffer.length) feed(player.buffer.shift()); });
});
$("log-jump").addEventListener("click", () => {
  if (player.summary) jump(player.summary.start + Number($("log-at").value || 0));
});
$("log-export").addEventListener("click", () => {
  if (!player.summary) return;
  const shown = state.current && state.current.plot ? state.current.plot.scales.x : null;
  const zoomed = shown && shown.min != null && !state.current.following;
  const [from, to] = zoomed ? [shown.min, shown.max] : [player.summary.start, player.summary.end];
  const span = zoomed ? { from, to } : { from_ns: player.summary.start_ns, to_ns: player.summary.end_ns };
  const format = $("log-format").value;
  api("/api/logs/export", { log: player.log, ...span, format }).then((r) => r.blob()).then((blob) => {
    const link = document.createElement("a");
    link.href = URL.createObjectURL(blob);
    link.download = `${$("log-select").selectedOptions[0].textContent.replace(/\.[^.]*$/, "")}-${from.toFixed(3)}-${to.toFixed(3)}.${format === "candump" ? "log" : format}`;
    link.click();
    say(`exported ${blob.size} bytes`);
  }).catch((e) => say(e.message, true));
});

// ---- start ---------------------------------------------------------------------------------
$("pause").addEventListener("click", () => { state.paused = !state.paused; $("pause").classList.toggle("on", state.paused); });
$("mode").addEventListener("click", () => { state.fixed = !state.fixed; $("mode").textContent = state.fixed ? "fixed" : "scrolling"; state.dirty = true; });
$("filter").addEventListener("input", (e) => { state.filter = parseFilter(e.target.value); state.dirty = true; });
$("add-panel").addEventListener("click", addPanel);
$("send-once").addEventListener("click", sendOnce);
$("send-start").addEventListener("click", startPeriodic);
$("send-stop").addEventListener("click", stopPeriodic);

setInterval(() => {
  if (state.dirty && !state.paused) { drawTrace(); state.dirty = false; }
  drawBuses();
  drawTug();
}, 100);
setInterval(() => { for (const p of state.panels) if (p.dirty) { drawPlot(p); p.dirty = false; } }, 250);

// What tests and scripts read of the page.
window.bywire = {
  state,
  rows: () => [...document.querySelectorAll("#trace tbody tr")].map((tr) => [...tr.children].map((td) => td.textContent)),
  series: (panel) => state.panels[panel].series.map((s) => ({ signal: s.signal, x: s.x.slice(), y: s.y.slice(), samples: s.samples })),
  player,
  chooseLog,
  plotSignal,
};

fetch(withToken("/api/database")).then((r) => r.json()).then((db) => { state.database = db; buildTree(); connect(); setupLogs(); });
