// Foxglove's own WebSocket client subscribes to every channel `amiro monitor --foxglove` advertises and prints, one
// JSON object per line, the server's name, each advertised channel, and each message received (channel, log time in
// nanoseconds as a string, payload). It ends after the given number of milliseconds.
// Usage: node client.js ws://127.0.0.1:PORT MILLISECONDS
const { FoxgloveClient } = require("@foxglove/ws-protocol");
const WebSocket = require("ws");

const [url, millis] = process.argv.slice(2);
// The foxglove SDK's server negotiates `foxglove.sdk.v1`, the current name of the protocol this client speaks
// (`foxglove.websocket.v1`, inline schemas); the Foxglove app offers it the same way.
const client = new FoxgloveClient({
  ws: new WebSocket(url, ["foxglove.sdk.v1", FoxgloveClient.SUPPORTED_SUBPROTOCOL]),
});
const topics = new Map();
const subscriptions = new Map();
const out = (object) => process.stdout.write(JSON.stringify(object) + "\n");

client.on("serverInfo", (info) => out({ kind: "server", name: info.name }));
client.on("advertise", (channels) => {
  for (const channel of channels) {
    topics.set(channel.id, channel.topic);
    out({
      kind: "channel",
      topic: channel.topic,
      encoding: channel.encoding,
      schemaName: channel.schemaName,
      schemaEncoding: channel.schemaEncoding,
      schema: channel.schema,
    });
    subscriptions.set(client.subscribe(channel.id), channel.topic);
  }
});
client.on("message", ({ subscriptionId, timestamp, data }) => {
  out({
    kind: "message",
    topic: subscriptions.get(subscriptionId),
    log_time: timestamp.toString(),
    payload: JSON.parse(new TextDecoder().decode(data)),
  });
});
client.on("error", (error) => {
  process.stderr.write(`error: ${error}\n`);
  process.exit(1);
});
setTimeout(() => {
  client.close();
  process.exit(0);
}, Number(millis));
