#!/usr/bin/env node
// A stock Foxglove WebSocket client on `agp view`: @foxglove/ws-protocol's FoxgloveClient
// (the protocol's published npm package) over the `ws` package, decoding each channel with
// the protobuf schema the server advertises (protobufjs). It subscribes to every channel,
// waits until the required topics and scene entities have arrived (or a timeout), and
// prints on stdout, as JSON, what it received: per topic its schema, message count and last
// message decoded (large byte fields replaced by their length), and every scene entity
// seen, by topic and id.
//
//   node client.cjs --url ws://127.0.0.1:8765 [--timeout-s 60] [--min-s 0]
//                   [--require /robot ...] [--require-entity /estimate:object_estimate ...]
//                   [--subprotocol NAME]
//
// Exit status: 0 when every requirement was met, 1 when not (the JSON says what is
// missing), 2 on bad arguments.
//
// It offers the package's own subprotocol, `FoxgloveClient.SUPPORTED_SUBPROTOCOL`
// ("foxglove.websocket.v1", the protocol's original name, which Lichtblick and older Foxglove
// releases offer too), as a stock client does; `--subprotocol NAME` offers another
// (`foxglove.sdk.v1`, the SDK's name for the same protocol). The dump's `subprotocol` is
// the one the server chose.
"use strict";

const { FoxgloveClient } = require("@foxglove/ws-protocol");
const WebSocket = require("ws");
const protobuf = require("protobufjs");
const { FileDescriptorSet } = require("protobufjs/ext/descriptor");

function parseArgs(argv) {
  const out = {
    url: "ws://127.0.0.1:8765",
    timeoutS: 60,
    minS: 0,
    require: [],
    requireEntity: [],
    subprotocol: FoxgloveClient.SUPPORTED_SUBPROTOCOL,
  };
  for (let i = 0; i < argv.length; i++) {
    const a = argv[i];
    const next = () => {
      if (i + 1 >= argv.length) {
        console.error(`foxglove-client: ${a} needs a value`);
        process.exit(2);
      }
      return argv[++i];
    };
    if (a === "--url") out.url = next();
    else if (a === "--timeout-s") out.timeoutS = Number(next());
    else if (a === "--min-s") out.minS = Number(next());
    else if (a === "--require") out.require.push(next());
    else if (a === "--require-entity") out.requireEntity.push(next());
    else if (a === "--subprotocol") out.subprotocol = next();
    else {
      console.error(`foxglove-client: unknown argument ${a}`);
      process.exit(2);
    }
  }
  return out;
}

const args = parseArgs(process.argv.slice(2));
const started = Date.now();
const channels = new Map(); // channel id -> { topic, schemaName, encoding, type }
const topics = {}; // topic -> { schemaName, count, last }
const entities = {}; // topic -> { id -> entity summary }
const errors = [];
let serverInfo = null;
let subprotocol = null;
let lastTime = null;

function decoderFor(channel) {
  if (channel.encoding !== "protobuf" || channel.schemaEncoding !== "protobuf") {
    return null;
  }
  const set = FileDescriptorSet.decode(Buffer.from(channel.schema, "base64"));
  const root = protobuf.Root.fromDescriptor(set);
  return root.lookupType(channel.schemaName);
}

// Byte fields (a grid's or an image's pixels) become their length.
function trimBytes(obj) {
  if (obj instanceof Uint8Array) return { bytes: obj.length };
  if (Array.isArray(obj)) return obj.map(trimBytes);
  if (obj && typeof obj === "object") {
    const out = {};
    for (const [k, v] of Object.entries(obj)) out[k] = trimBytes(v);
    return out;
  }
  return obj;
}

function entitySummary(e) {
  const count = (k) => (e[k] || []).length;
  return {
    frame_id: e.frame_id,
    timestamp: e.timestamp,
    cylinders: (e.cylinders || []).map((c) => ({ pose: c.pose, size: c.size })),
    arrows: count("arrows"),
    spheres: count("spheres"),
    lines: (e.lines || []).map((l) => ({ type: l.type, points: (l.points || []).length })),
    triangles: (e.triangles || []).map((t) => (t.points || []).length),
    texts: (e.texts || []).map((t) => t.text),
    metadata: Object.fromEntries((e.metadata || []).map((kv) => [kv.key, kv.value])),
  };
}

function missing() {
  const m = [];
  for (const t of args.require) if (!topics[t] || topics[t].count === 0) m.push(t);
  for (const te of args.requireEntity) {
    const [t, id] = te.split(":");
    if (!entities[t] || !entities[t][id]) m.push(te);
  }
  return m;
}

function finish(reason) {
  const m = missing();
  const dump = {
    url: args.url,
    offered: args.subprotocol,
    subprotocol,
    server: serverInfo && { name: serverInfo.name, capabilities: serverInfo.capabilities },
    seconds: (Date.now() - started) / 1000,
    ended: reason,
    time: lastTime,
    channels: [...channels.values()].map((c) => ({ topic: c.topic, schemaName: c.schemaName, encoding: c.encoding })),
    topics,
    entities,
    errors,
    missing: m,
  };
  process.stdout.write(JSON.stringify(dump, null, 1) + "\n", () => process.exit(m.length === 0 ? 0 : 1));
}

const ws = new WebSocket(args.url, [args.subprotocol]);
const client = new FoxgloveClient({ ws });
const timer = setTimeout(() => finish("timeout"), args.timeoutS * 1000);

client.on("open", () => {
  subprotocol = ws.protocol;
});
client.on("serverInfo", (info) => {
  serverInfo = info;
});
client.on("error", (e) => errors.push(String(e && e.message ? e.message : e)));
client.on("close", () => {
  clearTimeout(timer);
  finish("closed");
});
client.on("time", (t) => {
  lastTime = Number(t.timestamp);
});
client.on("advertise", (list) => {
  for (const c of list) {
    let type = null;
    try {
      type = decoderFor(c);
    } catch (e) {
      errors.push(`${c.topic}: cannot load the schema ${c.schemaName}: ${e.message}`);
    }
    channels.set(c.id, { topic: c.topic, schemaName: c.schemaName, encoding: c.encoding, type, sub: null });
    channels.get(c.id).sub = client.subscribe(c.id);
  }
});
const bySub = () => new Map([...channels.entries()].map(([id, c]) => [c.sub, id]));
client.on("message", ({ subscriptionId, data }) => {
  const id = bySub().get(subscriptionId);
  const c = channels.get(id);
  if (!c) return;
  const t = (topics[c.topic] ||= { schemaName: c.schemaName, count: 0, last: null });
  t.count += 1;
  if (!c.type) return;
  let msg;
  try {
    const bytes = new Uint8Array(data.buffer, data.byteOffset, data.byteLength);
    msg = c.type.toObject(c.type.decode(bytes), { longs: Number, enums: String, defaults: false });
  } catch (e) {
    errors.push(`${c.topic}: cannot decode a ${c.schemaName}: ${e.message}`);
    return;
  }
  if (c.schemaName === "foxglove.SceneUpdate") {
    const byId = (entities[c.topic] ||= {});
    for (const e of msg.entities || []) byId[e.id] = entitySummary(e);
    t.last = { entities: (msg.entities || []).map((e) => e.id), deletions: (msg.deletions || []).length };
  } else {
    t.last = trimBytes(msg);
  }
  if (missing().length === 0 && (Date.now() - started) / 1000 >= args.minS) {
    clearTimeout(timer);
    client.close();
  }
});
