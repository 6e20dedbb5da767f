// A Foxglove WebSocket client (the protocol's reference TypeScript implementation,
// @foxglove/ws-protocol, over the `ws` package) for tests/runs/test_live.py.
//
//   node client.mjs ws://127.0.0.1:PORT SECONDS
//
// Connects, subscribes to every advertised channel, and prints one JSON line per
// event on stdout: {"op": "advertise", "channels": [...]}, {"op": "message", "topic",
// "encoding", "schemaName", "timestamp", "data": base64} and {"op": "time", "timestamp"}.
// Ends when the server closes the connection, or after SECONDS.
import { FoxgloveClient } from "@foxglove/ws-protocol";
import { WebSocket } from "ws";

const [url, seconds] = process.argv.slice(2);
const out = (obj) => process.stdout.write(JSON.stringify(obj) + "\n");
const channels = new Map(); // subscription id -> channel
const client = new FoxgloveClient({
  ws: new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]),
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
  process.exit(0);
});
