// A Foxglove WebSocket client (the protocol's reference TypeScript implementation,
// @foxglove/ws-protocol, over the `ws` package) for tests/runs/test_live.py.
//
//   node client.cjs ws://127.0.0.1:PORT SECONDS OUT.jsonl
//
// Connects, subscribes to every advertised channel, and writes one JSON line per
// event to OUT.jsonl (a file: a full pipe would stall the client and the server
// would drop it): {"op": "advertise", "channels": [...]}, {"op": "message", "topic",
// "encoding", "schemaName", "timestamp", "data": base64} and {"op": "time", "timestamp"}.
// Ends when the server closes the connection, or after SECONDS.
const { FoxgloveClient } = require("@foxglove/ws-protocol");
const { WebSocket } = require("ws");

const fs = require("fs");

const [url, seconds, outPath] = process.argv.slice(2);
const file = fs.createWriteStream(outPath);
const out = (obj) => file.write(JSON.stringify(obj) + "\n");
const channels = new Map(); // subscription id -> channel
// The foxglove-sdk server speaks protocol v1 under the subprotocol name
// "foxglove.sdk.v1" (and refuses the handshake otherwise); the Foxglove app offers
// both names, and so does this client.
const client = new FoxgloveClient({
  ws: new WebSocket(url, ["foxglove.sdk.v1", FoxgloveClient.SUPPORTED_SUBPROTOCOL]),
});
const timer = setTimeout(() => client.close(), Number(seconds) * 1000);

client.on("serverInfo", (info) => out({ op: "serverInfo", name: info.name, capabilities: info.capabilities }));
client.on("advertise", (advertised) => {
  out({ op: "advertise", channels: advertised });
  for (const channel of advertised) {
    channels.set(client.subscribe(channel.id), channel);
  }
});
client.on("message", ({ subscriptionId, timestamp, data }) => {
  const channel = channels.get(subscriptionId);
  out({
    op: "message",
    topic: channel.topic,
    encoding: channel.encoding,
    schemaName: channel.schemaName,
    timestamp: timestamp.toString(),
    data: Buffer.from(data.buffer, data.byteOffset, data.byteLength).toString("base64"),
  });
});
client.on("time", ({ timestamp }) => out({ op: "time", timestamp: timestamp.toString() }));
client.on("error", (err) => {
  process.stderr.write(`client error: ${err?.message ?? err}\n`);
});
client.on("close", () => {
  clearTimeout(timer);
  out({ op: "close" });
  file.end(() => process.exit(0));
});
